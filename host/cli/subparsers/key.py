"""``odocan key derive``: one robot's SecOC key, derived from the fleet key, into a key file.

``odocan fleet --secoc-key FLEET`` provisions each robot with its own key (``sim.provision``:
NIST SP 800-108 counter mode, PRF AES-128-CMAC, Context = the robot's name). A robot run on its
own -- ``odocan firmware --secoc-key`` with ``odocan bridge --secoc-key`` -- needs that same key
in a file; this command writes it:

    odocan key derive --fleet-key fleet.key --robot robot001 --out robot001.key

The file is 32 hex digits and a newline (``--format raw``: the 16 bytes; ``--secoc-key`` reads
both), mode 0600, written to a
temporary file in the same directory and linked into place, so no reader ever sees half a key
and an existing file is never overwritten (``--force`` replaces it, still atomically). The key is
never printed. Bad input (an unreadable fleet key, a name that is not ASCII, an existing or
unwritable output) is one line ``error: ...`` naming the path, exit 2.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from odocan.host.outputs import check_distinct
from odocan.host.protocol.secoc import load_secoc_key
from odocan.sim.exceptions import ConfigurationError, OdocanError
from odocan.sim.provision import robot_key

FORMATS = ("hex", "raw")


def add_subparser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register ``odocan key derive`` (one action today; the word leaves room for others)."""
    parser = subparsers.add_parser(
        "key",
        help="derive one robot's SecOC key file from the fleet key",
        description="derive: write robot NAME's SecOC key, derived from the fleet key exactly "
        "as odocan fleet --secoc-key provisions that robot (NIST SP 800-108 counter mode, "
        "AES-128-CMAC, Context = NAME), for odocan firmware/bridge --secoc-key. The file is "
        "mode 0600, written atomically; an existing file is kept unless --force.",
    )
    parser.add_argument("action", choices=("derive",), help="what to do with keys")
    parser.add_argument("--fleet-key", required=True, metavar="PATH", help="the fleet key file")
    parser.add_argument("--robot", required=True, metavar="NAME", help="the robot (robot001 ...)")
    parser.add_argument("--out", required=True, metavar="PATH", help="the robot's key file")
    parser.add_argument(
        "--format",
        choices=FORMATS,
        default="hex",
        help="hex: 32 hex digits and a newline; raw: the 16 bytes (both are --secoc-key files)",
    )
    parser.add_argument("--force", action="store_true", help="replace an existing --out")
    parser.set_defaults(func=_do_key_derive)


def _do_key_derive(args: argparse.Namespace) -> int:
    name = robot_name(args.robot)
    check_distinct([("--out", Path(args.out))], [("--fleet-key", Path(args.fleet_key))])
    key = robot_key(load_secoc_key(args.fleet_key), name)
    data = key if args.format == "raw" else (key.hex() + "\n").encode("ascii")
    write_key_file(Path(args.out), data, force=args.force)
    print(f"wrote {name}'s SecOC key to {args.out} (mode 0600)")
    return 0


def robot_name(name: str) -> str:
    """``name`` if it can be a fleet robot's SP 800-108 Context: non-empty printable ASCII
    without spaces (as ``robot001``); else a ``ConfigurationError``."""
    if not name or not name.isascii() or not name.isprintable() or " " in name:
        raise ConfigurationError(f"robot name {name!r}: expected printable ASCII, no spaces")
    return name


def write_key_file(path: Path, data: bytes, *, force: bool) -> None:
    """Write ``data`` (a key file's bytes) to ``path``, mode 0600, atomically: a
    temporary file in the same directory, linked into place (which fails if ``path`` exists)
    or, with ``force``, renamed over it. Errors are ``OdocanError`` naming ``path``."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise OdocanError(f"cannot write SecOC key {path}: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "wb") as out:  # mkstemp: mode 0600
            out.write(data)
            out.flush()
            os.fsync(out.fileno())
        if force:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)
    except FileExistsError:
        raise OdocanError(f"SecOC key {path} exists: not overwritten (--force)") from None
    except OSError as exc:
        raise OdocanError(f"cannot write SecOC key {path}: {exc.strerror or exc}") from None
    finally:
        Path(tmp).unlink(missing_ok=True)

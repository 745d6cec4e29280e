"""The fault model: what ``--faults`` text means, parsed and validated into a ``FaultSpec``.

Every key is optional, comma-separated::

    drop=P          each frame is lost with probability P
    burst=P:LEN     with probability P a burst starts: this frame and the next LEN - 1 are lost
    dup=P           the frame goes on the bus twice (a retransmission of the same bits)
    delay=P:MS      the frame is held back and released MS ms later (by the wrapped clock), so
                    frames sent meanwhile overtake it: reordering
    flip=P[:BITS]   BITS distinct random bits of the payload are inverted (never the ID); BITS
                    defaults to 1 (a single-bit error, which every CRC detects)
    babble=RATE[:ID[:T:DUR]]
                    a babbling node at RATE frames per second of the sender's time, as a Poisson
                    process: random frames (11/29-bit IDs, DLC 0-8, random payloads, 10% error
                    frames, 10% remote frames); with ID (0x050 or 80) a stuck node sending data
                    frames of 8 random bytes on that one ID (29-bit above 0x7FF, written with
                    more than 3 hex digits: 0x00000900, not 0x900), which on a
                    bit-timed bus wins arbitration against every higher ID; with T:DUR it
                    babbles only from T s for DUR s (else from the first frame, for ever).
                    RATE is on the wire: ``two_handles`` splits it between the rig's handles
    busoff=T:DUR    at T s the transmitter's error counter climbs past 255 (32 failed attempts,
                    +8 each, through the warning and error-passive limits): bus-off for DUR s,
                    then recovery after 128 occurrences of 11 recessive bits (at ``bitrate``)
    stall=T:DUR     the firmware's MCU halted (a debugger halt, a hung main loop) from T s for
                    DUR s: it runs no tick and no receive interrupt; its CAN controller keeps
                    receiving into its hardware FIFO, which holds the first frames and
                    overruns the rest (``sim.board``: FIFO-locked, as bxCAN; a halt shorter
                    than ``sim.board.HALT_AFTER_S`` is only a late tick there); then it resumes
                    with its RAM as it was (the firmware sees the time it lost); a stall
                    from the first tick (T < 10 ms) is a late power-up: the firmware never ran
                    to set its controller up, so it takes none of those frames
    reboot=T[:DUR]  the firmware's MCU reset at T s: RAM lost (a new firmware, INIT, priming on
                    its first encoder frame as at power-up), the NVM cell kept, the frames
                    waiting in its receive FIFO lost; DUR s of boot time (default 0) during
                    which it runs nothing and its CAN controller, not yet set up, takes no
                    frame. stall and reboot act on the firmware (the MCU), not on a bus handle:
                    only the lockstep rig (``odocan run``) injects them (``sim.mcufaults``);
                    both may be given any number of times (a HIL bench's script of hangs and
                    resets: ``stall=2:1,stall=6:0.5,reboot=9,reboot=14:0.3``)
    seed=N          the seed of every random draw (the same seed gives the same faults);
                    without it, the command's ``--seed`` (``parse(text, seed=...)``), else 0

P in [0, 1]; LEN >= 1; MS >= 0; 1 <= BITS <= 64; RATE >= 0 frames/s; 0 <= ID <= 0x1FFFFFFF;
T, DUR >= 0 s (a bus-off's and a stall's DUR > 0). Each key but stall and reboot is given at
most once (one bus-off); the MCU's episodes, kept in time order, may not overlap nor touch (a
reset's instant or boot time within a halt, two halts that are one: give them apart), save a
reset at the very end of a halt (a watchdog's, ``stall=3:2,reboot=5``). A frame
suffers at most one of drop, burst, dup, delay, flip: one uniform draw per frame is split into
intervals of those widths (``exclusive_edges``: each has exactly its probability; their sum must
be <= 1). ``sim.faults.FaultInjectingBus`` injects what a spec says.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import Any

from odocan.sim.exceptions import ConfigurationError

MAX_CAN_ID = 0x1FFFFFFF  # the largest 29-bit identifier
FAULT_KINDS = ("drop", "burst", "dup", "delay", "flip", "babble", "busoff", "refused")
_EXCLUSIVE = ("drop", "burst", "dup", "delay", "flip")  # at most one of these per frame
MCU_KEYS = ("stall", "reboot")  # the firmware MCU's own faults, not a bus handle's
_KEYS = ("drop", "burst", "dup", "delay", "flip", "babble", "busoff", "stall", "reboot", "seed")


ECHO_CHARS = 60  # of a value said back: a 5 000-digit one made a 5 kB "line"


def _fail(key: str, value: str, why: str) -> ConfigurationError:
    said = value if len(value) <= ECHO_CHARS else value[:ECHO_CHARS] + "..."
    return ConfigurationError(f"faults: {key}={said}: {why}")


@dataclass(frozen=True)
class BusOff:
    """One episode (bus-off, a babble window, a stall, a reboot and its boot time): from
    ``at_s`` (the sender's time; the rig's simulated time for the MCU's) for ``duration_s``."""

    at_s: float
    duration_s: float


@dataclass(frozen=True)
class FaultSpec:
    """What to inject (see the module docstring); validated at construction."""

    drop: float = 0.0
    burst: float = 0.0
    burst_len: int = 1
    dup: float = 0.0
    delay: float = 0.0
    delay_ms: float = 0.0
    flip: float = 0.0
    flip_bits: int = 1
    babble: float = 0.0  # frames/s
    babble_id: int | None = None  # None: random IDs
    babble_window: BusOff | None = None  # None: from the first frame, for ever
    busoff: BusOff | None = None
    stalls: tuple[BusOff, ...] = ()  # the MCU halted from at_s for duration_s, in time order
    reboots: tuple[BusOff, ...] = ()  # the MCU reset at at_s, booting for duration_s, in order
    seed: int = 0

    def __post_init__(self) -> None:
        for name in _EXCLUSIVE:
            _check_probability(name, getattr(self, name))
        total = sum(getattr(self, name) for name in _EXCLUSIVE)
        if total > 1.0:
            raise ConfigurationError(
                f"faults: drop + burst + dup + delay + flip = {total:g} > 1 "
                "(a frame suffers at most one of them)"
            )
        _check_int("burst", self.burst_len, 1, None, "LEN")
        _check_float("delay", self.delay_ms, "MS")
        _check_int("flip", self.flip_bits, 1, 64, "BITS")
        _check_float("babble", self.babble, "RATE")
        if self.babble_id is not None:
            _check_int("babble", self.babble_id, 0, MAX_CAN_ID, "ID")
        if self.babble_window is not None:
            _check_float("babble", self.babble_window.at_s, "T")
            _check_float("babble", self.babble_window.duration_s, "DUR")
            if self.babble_window.duration_s == 0:  # a window of no length: no babble at all
                raise _fail("babble", f"{_num(self.babble)}:0x{self.babble_id or 0:03X}:"
                            f"{_num(self.babble_window.at_s)}:0",
                            "DUR must be > 0 s (a babble window of no length; leave babble out)")
        if self.busoff is not None:
            _check_float("busoff", self.busoff.at_s, "T")
            _check_float("busoff", self.busoff.duration_s, "DUR")
            if self.busoff.duration_s == 0:  # only the recovery time: no bus-off at all
                raise _fail("busoff", f"{_num(self.busoff.at_s)}:0",
                            "DUR must be > 0 s (a bus-off of no length; leave busoff out)")
        self._check_mcu()
        _check_int("seed", self.seed, None, None, "N")

    def _check_mcu(self) -> None:
        """stall and reboot: finite times >= 0, a stall of some length, no two overlapping or
        touching (module docstring); both kept in time order, so that the same episodes in any
        order are the same spec (the same bytes, the same canonical text)."""
        for key in MCU_KEYS:
            for episode in getattr(self, f"{key}s"):
                _check_float(key, episode.at_s, "T")
                _check_float(key, episode.duration_s, "DUR")
                if key == "stall" and episode.duration_s == 0:
                    raise _fail("stall", f"{_num(episode.at_s)}:0",
                                "DUR must be > 0 s (a stall of no length; leave stall out)")
            object.__setattr__(self, f"{key}s", tuple(sorted(getattr(self, f"{key}s"),
                                                             key=lambda e: e.at_s)))
        episodes = mcu_episodes(self)
        for (key, one), (then, other) in itertools.pairwise(episodes):
            end_s = one.at_s + one.duration_s
            watchdog = key == "stall" and then == "reboot" and other.at_s == end_s
            if other.at_s <= end_s and not watchdog:
                raise ConfigurationError(
                    f"faults: {key}={_episode_text(one, key)} and "
                    f"{then}={_episode_text(other, then)} overlap or touch (a reset or its boot "
                    "time within a halt, two halts that are one): give them apart")

    @classmethod
    def parse(cls, text: str, *, seed: int = 0) -> FaultSpec:
        """A spec from ``--faults`` text such as ``drop=0.01,burst=0.001:5,seed=3`` ("" = none);
        ``seed``: the spec's seed when the text sets none (a command's ``--seed``: runs at several
        seeds draw several fault streams, not the one stream of seed 0)."""
        values: dict[str, Any] = {"seed": seed}
        seen: set[str] = set()
        items = [part.strip() for part in text.split(",")] if text.strip() else []
        for item in items:
            if not item:
                raise ConfigurationError(f"faults: {text!r}: an empty item (a comma too many?)")
            key, sep, value = (s.strip() for s in item.partition("="))
            if not sep:
                raise ConfigurationError(f"faults: {item!r}: expected KEY=VALUE")
            if key not in _KEYS:
                raise ConfigurationError(f"faults: unknown key {key!r} (known: {', '.join(_KEYS)})")
            if key in seen and key not in MCU_KEYS:  # a script of hangs and resets: any number
                raise ConfigurationError(f"faults: {key} given twice")
            seen.add(key)
            if key in MCU_KEYS:
                values[f"{key}s"] = (*values.get(f"{key}s", ()), _parse_value(key, value)[key])
            else:
                values.update(_parse_value(key, value))
        return cls(**values)

    @property
    def active(self) -> bool:
        """True when anything at all is injected."""
        return self != FaultSpec(seed=self.seed)

    @property
    def mcu_active(self) -> bool:
        """True when the firmware's MCU stalls or reboots (``sim.mcufaults``)."""
        return bool(self.stalls or self.reboots)

    def bus_part(self) -> FaultSpec:
        """What a bus handle injects (``FaultInjectingBus``): this spec without the MCU's
        stall and reboot."""
        return replace(self, stalls=(), reboots=())

    def __str__(self) -> str:
        """The canonical ``--faults`` text (``parse(str(spec)) == spec``)."""
        items = [
            f"{name}={_num(getattr(self, name))}" for name in ("drop", "dup") if getattr(self, name)
        ]
        if self.burst:
            items.append(f"burst={_num(self.burst)}:{self.burst_len}")
        if self.delay:
            items.append(f"delay={_num(self.delay)}:{_num(self.delay_ms)}")
        if self.flip:
            items.append(f"flip={_num(self.flip)}:{self.flip_bits}")
        if self.babble:
            items.append(f"babble={_babble_text(self)}")
        if self.busoff is not None:
            items.append(f"busoff={_episode_text(self.busoff)}")
        for key in MCU_KEYS:
            items += [f"{key}={_episode_text(e, key)}" for e in getattr(self, f"{key}s")]
        items.append(f"seed={self.seed}")
        return ",".join(items)


def _babble_text(spec: FaultSpec) -> str:
    """RATE[:ID[:T:DUR]] of ``babble=``."""
    text = _num(spec.babble)
    if spec.babble_id is not None:
        text += f":0x{spec.babble_id:0{3 if spec.babble_id <= 0x7FF else 8}X}"
        if spec.babble_window is not None:
            window = spec.babble_window
            text += f":{_num(window.at_s)}:{_num(window.duration_s)}"
    return text


def _episode_text(episode: BusOff, key: str = "busoff") -> str:
    """T:DUR of an episode (a reboot's T alone when it boots in no time)."""
    if key == "reboot" and not episode.duration_s:
        return _num(episode.at_s)
    return f"{_num(episode.at_s)}:{_num(episode.duration_s)}"


def _num(value: float) -> str:
    """A number as short as it reads back exactly: 0.01, 100, 2.5."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def _check_probability(key: str, p: object) -> None:
    if isinstance(p, bool) or not isinstance(p, int | float) or not 0.0 <= p <= 1.0:
        raise _fail(key, repr(p), "P must be a probability in [0, 1]")


def _check_float(key: str, value: object, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise _fail(key, repr(value), f"{what} must be a finite number >= 0")
    if value < 0:
        raise _fail(key, repr(value), f"{what} must be a finite number >= 0")


def _check_int(key: str, value: object, lo: int | None, hi: int | None, what: str) -> None:
    if (
        isinstance(value, bool)
        or not isinstance(value, int)
        or (lo is not None and value < lo)
        or (hi is not None and value > hi)
    ):
        bounds = f" in [{lo}, {hi}]" if hi is not None else (f" >= {lo}" if lo is not None else "")
        raise _fail(key, repr(value), f"{what} must be an integer{bounds}")


def _number(key: str, text: str, what: str, whole: str = "") -> float:
    """Field ``what`` of ``key=whole`` (``text``: the field; the whole value said back in an
    error, ``delay=0.1:abc``, not ``delay=abc``)."""
    try:
        if "_" in text or text != text.strip():  # float() reads "1_0" as 10, " 2" as 2
            raise ValueError(text)
        value = float(text)
    except ValueError:
        raise _fail(key, whole or text, f"{what} is not a number") from None
    if not math.isfinite(value):
        raise _fail(key, whole or text, f"{what} must be finite")
    return value


def _integer(key: str, text: str, what: str, whole: str = "") -> int:
    """As ``_number``, an integer."""
    try:
        return int(text)
    except ValueError:
        raise _fail(key, whole or text, f"{what} is not an integer") from None


def _fields(key: str, value: str, shape: str, optional_second: bool = False) -> list[str]:
    parts = value.split(":")
    if len(parts) == 2 or (optional_second and len(parts) == 1):
        return parts
    raise _fail(key, value, f"expected {key}={shape}")


def _parse_value(key: str, value: str) -> dict[str, Any]:
    """The FaultSpec fields of one ``key=value`` item."""
    if key in ("drop", "dup"):
        return {key: _number(key, value, "P")}
    if key == "babble":
        return _parse_babble(value)
    if key == "seed":
        return {key: _integer(key, value, "N")}
    if key == "burst":
        p, n = _fields(key, value, "P:LEN")
        return {"burst": _number(key, p, "P", value),
                "burst_len": _integer(key, n, "LEN", value)}
    if key == "delay":
        p, ms = _fields(key, value, "P:MS")
        return {"delay": _number(key, p, "P", value),
                "delay_ms": _number(key, ms, "MS", value)}
    if key == "flip":
        parts = _fields(key, value, "P[:BITS]", optional_second=True)
        bits = _integer(key, parts[1], "BITS", value) if len(parts) == 2 else 1
        return {"flip": _number(key, parts[0], "P", value), "flip_bits": bits}
    if key == "reboot":
        parts = _fields(key, value, "T[:DUR]", optional_second=True)
        boot_s = _number(key, parts[1], "DUR", value) if len(parts) == 2 else 0.0
        return {key: _episode(key, value, _number(key, parts[0], "T", value), boot_s)}
    at, duration = _fields(key, value, "T:DUR")  # busoff, stall
    return {key: _episode(key, value, _number(key, at, "T", value),
                          _number(key, duration, "DUR", value))}


def _episode(key: str, value: str, at_s: float, duration_s: float) -> BusOff:
    """T and DUR of ``key=value``, refused as given when either is negative."""
    for what, number in (("T", at_s), ("DUR", duration_s)):
        if number < 0:
            raise _fail(key, value, f"{what} must be a finite number >= 0")
    return BusOff(at_s, duration_s)


def two_handles(spec: FaultSpec) -> tuple[FaultSpec, FaultSpec]:
    """One ``--faults`` spec as the rig's two faulted handles take it (``odocan run``: the
    motor controller's and the firmware's sends): the frame faults and bus-off on each (the
    firmware's drawn from ``seed + 1``), the babbling node's RATE split in half between them, so
    that RATE is what reaches the wire, as a CAN tool's interactive generator means it (two
    Poisson streams of RATE / 2 are one of RATE; halving a float is exact). The MCU's stall and
    reboot go with the firmware's (``RigConfig.fw_faults``), not the motor controller's."""
    half = replace(spec, babble=spec.babble / 2)
    return half.bus_part(), replace(half, seed=spec.seed + 1)


def exclusive_edges(spec: FaultSpec) -> list[tuple[float, str]]:
    """Cumulative interval ends of the exclusive faults (zero-width ones left out)."""
    edges = []
    total = 0.0
    for kind in _EXCLUSIVE:
        p = float(getattr(spec, kind))
        if p:
            total += p
            edges.append((total, kind))
    return edges


def _parse_babble(value: str) -> dict[str, Any]:
    """``babble=RATE[:ID[:T:DUR]]``: the rate (frames/s), the one CAN ID, the window."""
    parts = value.split(":")
    if len(parts) not in (1, 2, 4):
        raise _fail("babble", value, "expected babble=RATE[:ID[:T:DUR]]")
    fields: dict[str, Any] = {"babble": _number("babble", parts[0], "RATE", value)}
    if len(parts) >= 2:
        try:
            fields["babble_id"] = int(parts[1], 0)
        except ValueError:
            raise _fail("babble", value, "ID is not an integer (0x050 or 80)") from None
        _check_id_width(value, parts[1].strip(), fields["babble_id"])
    if len(parts) == 4:
        at_s = _number("babble", parts[2], "T", value)
        fields["babble_window"] = BusOff(at_s, _number("babble", parts[3], "DUR", value))
    return fields


def mcu_episodes(spec: FaultSpec) -> list[tuple[str, BusOff]]:
    """Every stall and reboot of ``spec`` as (key, episode), in time order (a reset at a halt's
    very end after the halt)."""
    return sorted([(key, e) for key in MCU_KEYS for e in getattr(spec, f"{key}s")],
                  key=lambda pair: (pair[1].at_s, pair[0] == "reboot"))


def mcu_text(key: str, episode: BusOff) -> str:
    """``key=...`` of an MCU episode (stall, reboot), as ``--faults`` writes it."""
    return f"{key}={_episode_text(episode, key)}"


def mcu_refused(spec: FaultSpec) -> ConfigurationError:
    """The one-line refusal of stall or reboot where no rig steps the MCU (a bus handle, a live
    node's ``--faults``): silently dropped, a CI job would believe it tested a hang."""
    keys = ", ".join(k for k in MCU_KEYS if getattr(spec, f"{k}s"))
    return ConfigurationError(
        f"faults: {keys}: the firmware MCU's faults, injected by the lockstep rig only (odocan "
        "run); on a live bus, SIGSTOP/SIGCONT or restart the firmware process")


def _check_id_width(value: str, text: str, can_id: int) -> None:
    """An ID above 0x7FF is a 29-bit ID, but written as an 11-bit one (at most 3 hex digits, or
    a decimal under 4096: ``0x900``) it is most likely a typo for one: refused, with how to
    write the 29-bit ID it would be (``babble=100:0x900`` babbled 29-bit frames without a
    word, losing arbitration to every 11-bit ID)."""
    digits = text[2:] if text.lower().startswith("0x") else None
    looks_11_bit = len(digits) <= 3 if digits is not None else can_id < 0x1000
    if can_id > 0x7FF and looks_11_bit:
        raise _fail("babble", value, f"ID {text} is above 0x7FF, the largest 11-bit ID; for a "
                    f"29-bit ID write its 8 hex digits (0x{can_id:08X})")


__all__ = ["FAULT_KINDS", "MCU_KEYS", "BusOff", "FaultSpec", "exclusive_edges", "mcu_episodes",
           "mcu_refused", "mcu_text"]

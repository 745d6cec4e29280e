"""SecOC provisioning figures (issue #18): what a key and an EPOCH file cost at start (no asserts).

* the fleet's per-robot key derivation (``sim.provision.robot_key``: one integer-only AES-CMAC
  of the Python firmware per robot), per robot and for a fleet of 500;
* ``FileNvm.write_epoch`` (``odocan firmware --nvm``): temporary file, fsync, rename, fsync of
  the directory: one per boot of the firmware process;
* a C firmware instance through the ABI (``odocan_fw_init`` + ``odocan_fw_provision_secoc``: key
  expansion with the static const tables, subkeys, the EPOCH write), per boot, through ctypes.

    python bench/secoc_provision.py [--robots 500] [--writes 50] [--boots 200]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from odocan.sim import cboard
from odocan.sim.board import FileNvm, NvmCell
from odocan.sim.provision import robot_key
from odocan.sim.rig import firmware_params
from odocan.sim.robot import load

KEY = bytes(range(16))


def print_derivation(robots: int) -> None:
    """Per-robot key derivation, every robot of a fleet of ``robots``."""
    names = [f"robot{i:03d}" for i in range(1, robots + 1)]
    start = time.perf_counter()
    for name in names:
        robot_key(KEY, name)
    total_s = time.perf_counter() - start
    print(f"robot_key (Python integer-only CMAC): {total_s / robots * 1e6:.0f} us per robot, "
          f"{total_s * 1e3:.0f} ms for a fleet of {robots}")


def print_nvm_writes(writes: int) -> None:
    """FileNvm.write_epoch in a temporary directory: median and worst (ms)."""
    with tempfile.TemporaryDirectory() as tmp:
        nvm = FileNvm(Path(tmp) / "fw.nvm")
        times_ms = []
        for epoch in range(1, writes + 1):
            start = time.perf_counter()
            assert nvm.write_epoch(epoch)
            times_ms.append((time.perf_counter() - start) * 1e3)
    print(f"FileNvm.write_epoch (temp + fsync + rename + dir fsync) on {tempfile.gettempdir()}: "
          f"median {statistics.median(times_ms):.2f} ms, worst {max(times_ms):.2f} ms "
          f"over {writes} writes (one per firmware boot)")


class _Sink:
    def transmit(self, can_id: int, data: bytes) -> bool:
        return True


def print_c_boots(boots: int) -> None:
    """A C firmware instance created and provisioned, per boot (us, median), through ctypes."""
    params = firmware_params(load("pmir"), "exact")
    nvm = NvmCell()
    times_us = []
    for _ in range(boots):
        start = time.perf_counter()
        cboard.CEcu(_Sink(), params, secoc_key=KEY, nvm=nvm)
        times_us.append((time.perf_counter() - start) * 1e6)
    plain_us = []
    for _ in range(boots):
        start = time.perf_counter()
        cboard.CEcu(_Sink(), params)
        plain_us.append((time.perf_counter() - start) * 1e6)
    print(f"C firmware boot through ctypes: {statistics.median(times_us):.0f} us with the key "
          f"provisioned, {statistics.median(plain_us):.0f} us without (median of {boots})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--robots", type=int, default=500)
    parser.add_argument("--writes", type=int, default=50)
    parser.add_argument("--boots", type=int, default=200)
    args = parser.parse_args()
    print_derivation(args.robots)
    print_nvm_writes(args.writes)
    try:
        cboard.load_library()
    except cboard.FirmwareBuildError as exc:
        print(f"C: skipped ({exc})")
        return
    print_c_boots(args.boots)


if __name__ == "__main__":
    main()

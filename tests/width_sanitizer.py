"""A width sanitizer for the firmware, in the spirit of UBSan: every arithmetic result is checked.

Python integers never overflow, so a firmware line whose C has no equivalent on a 32-bit MCU with a
64-bit multiply (an ``i64 * i64`` product kept whole, a 127-bit sum) runs silently here. This
module rewrites the AST of every ``odocan.firmware.*`` module so that each ``+ - * << >> ** // %``,
each unary minus and each augmented assignment (``x += y`` becomes ``x = x + y``) goes through a
checker, loads the rewritten modules in place of the real ones (``instrumented_firmware``), and
records every site whose values leave the width C would give them.

The rule (exact):

* Every result must fit **i64 or u64**: ``-2^63 <= v < 2^64``.
* Exception, C's unsigned wrap: an ``a + b`` or ``a - b`` whose operands both fit may give a
  result one bit wider, ``-2^64 <= v < 2^65``, i.e. the carry or borrow of a u64 add/sub. C
  discards it (the ``wrap_*``/``& U64_MAX`` that follows) or reads it as the carry flag. Such a
  65-bit value may then only be wrapped, masked, compared, passed to a helper, or shifted right
  (``sum >> 64`` is the carry): as an operand of any other checked operation it is a violation
  (reported as ``operand``). A value reported where it was made is not reported again where it
  is used (a wider operand always was, or came from outside the firmware): each wide value counts
  once, at its site.
* ``-x`` of I64_MIN is 2^63, a u64 (C: ``0u - (uint64_t)x``): it fits.
* Not checked: ``& | ^ ~`` (they cannot widen 64-bit operands) and comparisons.
* Exempt: the bodies of the audited primitives, the functions of ``firmware/fixmath.py`` whose
  docstring gives their C form on a line starting with ``C:`` (``audited_helpers``). Their
  arguments are still checked where they are computed, at the call site.

Only integer values are checked (``bytes + bytes`` or a tuple concatenation is not arithmetic).

``standard_drives`` runs, through the instrumented firmware: lockstep random drives of every
integrator on both shipped robots, once more under dropped/duplicated/bit-flipped frames and a
bus-off; a closed-loop rig taking NAV_GOALs (both modes), ODOM_CONFIGs (a NACK, 32-bit counters),
ODOM_SET_POSE (200 km away), corrupt, short and overflowing frames; a rig whose firmware has a
SecOC key (genuine, forged, stale, unsigned and orphan commands, reboots, a failing NVM); the
golden vectors' edge cases;
and a sweep of the pure functions (sincos, atan2, chord factor, navigation laws, E2E sequence,
odometry steps of +-2^31 counts) over the edges of their C types. ``Recorder.seen`` tells which
arithmetic places ran (``firmware_sites`` lists them all). Run ``python -m tests.width_sanitizer
[seconds]`` to print the sites and the places not reached.
"""

from __future__ import annotations

import ast
import contextlib
import copy
import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import itertools
import operator
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, NamedTuple

import can

from tests import host_frames as hf

FIRMWARE_PACKAGE = "odocan.firmware"
FIRMWARE_DIR = Path(__file__).resolve().parent.parent / "firmware"
FIXMATH_MODULE = FIRMWARE_PACKAGE + ".fixmath"
CHECK_NAME = "__width_check__"
NEG_NAME = "__width_neg__"

WIDE_MIN = -(1 << 63)  # i64 min
WIDE_END = 1 << 64  # u64 max + 1
CARRY_MIN = -(1 << 64)  # a u64 - u64 borrow
CARRY_END = 1 << 65  # a u64 + u64 carry

_OPS: dict[type[ast.operator], tuple[str, Callable[[Any, Any], Any]]] = {
    ast.Add: ("+", operator.add),
    ast.Sub: ("-", operator.sub),
    ast.Mult: ("*", operator.mul),
    ast.LShift: ("<<", operator.lshift),
    ast.RShift: (">>", operator.rshift),
    ast.Pow: ("**", operator.pow),
    ast.FloorDiv: ("//", operator.floordiv),
    ast.Mod: ("%", operator.mod),
}
_BY_SYMBOL = {symbol: fn for symbol, fn in _OPS.values()}


def bits(value: int) -> int:
    """The C width ``value`` needs: its bit length unsigned if >= 0, two's complement if < 0."""
    return value.bit_length() if value >= 0 else (~value).bit_length() + 1


def _fits(value: int) -> bool:
    return WIDE_MIN <= value < WIDE_END


def _fits_carry(value: int) -> bool:
    return CARRY_MIN <= value < CARRY_END


@dataclass
class Site:
    """One arithmetic site that left its width, with the range of widths seen there."""

    path: str
    line: int
    col: int
    op: str
    what: str  # "result" or "operand"
    min_bits: int
    max_bits: int
    hits: int = 1

    def __str__(self) -> str:
        width = (
            f"{self.max_bits} bits"
            if self.min_bits == self.max_bits
            else f"{self.min_bits}-{self.max_bits} bits"
        )
        return f"{self.path}:{self.line}:{self.col}: '{self.op}' {self.what} {width} ({self.hits}x)"


@dataclass
class Recorder:
    """Collects the violating sites of every instrumented module (keyed by file:line:col:op)."""

    sites: dict[tuple[str, int, int, str, str], Site] = field(default_factory=dict)
    checks: int = 0  # how many checked operations ran (proof that the drives exercised the code)
    seen: set[tuple[str, int, int]] = field(default_factory=set)  # the sites that ran
    # the wide results reported already, by id: not reported again when they are used
    _made_wide: dict[int, int] = field(default_factory=dict, repr=False)

    def _flag(self, where: tuple[str, int, int], op: str, what: str, value: int) -> None:
        key = (*where, op, what)
        width = bits(value)
        site = self.sites.get(key)
        if site is None:
            self.sites[key] = Site(*where, op, what, width, width)
        else:
            site.hits += 1
            site.min_bits = min(site.min_bits, width)
            site.max_bits = max(site.max_bits, width)

    def binop(self, where: tuple[str, int, int], op: str, left: Any, right: Any) -> Any:
        """``left op right``, checked against the rule of the module docstring."""
        result = _BY_SYMBOL[op](left, right)
        self.seen.add(where)
        if type(result) is not int:
            return result
        self.checks += 1
        operands_fit = True
        for index, operand in enumerate((left, right)):
            if type(operand) is not int or _fits(operand):
                continue
            operands_fit = False
            carry_shifted = op == ">>" and index == 0
            made_here = self._made_wide.get(id(operand)) is operand
            if _fits_carry(operand) and not carry_shifted and not made_here:
                self._flag(where, op, "operand", operand)  # a carry used as a number
        if _fits(result):
            return result
        if op in "+-" and operands_fit and _fits_carry(result):
            return result
        if op in "+-" and not operands_fit:
            return result  # the wide operand is flagged already; do not count the site twice
        self._flag(where, op, "result", result)
        if len(self._made_wide) > 1 << 16:
            self._made_wide.clear()
        self._made_wide[id(result)] = result  # kept alive, so its id stays its own
        return result

    def neg(self, where: tuple[str, int, int], operand: Any) -> Any:
        """``-operand``, checked (``-I64_MIN`` is 2^63: a u64, as C's ``0u - x``)."""
        result = -operand
        if type(result) is int:
            self.checks += 1
            self.seen.add(where)
            if not _fits(operand):
                if _fits_carry(operand):
                    self._flag(where, "-x", "operand", operand)
            elif not _fits(result):
                self._flag(where, "-x", "result", result)
        return result

    def report(self) -> list[Site]:
        """The sites, in file and line order."""
        return sorted(self.sites.values(), key=lambda s: (s.path, s.line, s.col, s.op, s.what))


def audited_helpers(tree: ast.Module) -> frozenset[str]:
    """The fixmath functions whose docstring gives their C form (a line starting with ``C:``)."""
    names = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            doc = ast.get_docstring(node) or ""
            if any(line.strip().startswith("C:") for line in doc.splitlines()):
                names.add(node.name)
    return frozenset(names)


class Place(NamedTuple):
    """Where a checked operation is, and in which function (``<module>`` at module level)."""

    path: str
    line: int
    col: int
    function: str


def arithmetic_sites(source: str, path: str, exempt: frozenset[str] = frozenset()) -> set[Place]:
    """Every place the rewrite checks in ``source``."""
    found: set[Place] = set()

    def visit(node: ast.AST, function: str) -> None:
        for child in ast.iter_child_nodes(node):
            name = function
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                if child.name in exempt:
                    continue
                name = child.name
            checked = (isinstance(child, ast.BinOp | ast.AugAssign) and type(child.op) in _OPS) or (
                isinstance(child, ast.UnaryOp) and isinstance(child.op, ast.USub)
            )
            if checked:
                found.add(Place(path, child.lineno, child.col_offset, name))  # type: ignore[attr-defined]
            visit(child, name)

    visit(ast.parse(source, filename=path), "<module>")
    return found


def firmware_sites() -> set[Place]:
    """Every checked place of every firmware module (fixmath's audited helpers excepted)."""
    sites: set[Place] = set()
    for module in sorted(FIRMWARE_DIR.glob("*.py")):
        source = module.read_text(encoding="utf-8")
        exempt = audited_helpers(ast.parse(source)) if module.name == "fixmath.py" else frozenset()
        sites |= arithmetic_sites(source, f"firmware/{module.name}", exempt)
    return sites


def _load_ctx(node: ast.expr) -> ast.expr:
    """A copy of an assignment target usable as an expression (``x`` of ``x += 1``)."""
    clone = copy.deepcopy(node)
    for sub in ast.walk(clone):
        if hasattr(sub, "ctx"):
            sub.ctx = ast.Load()
    return clone


class _Rewriter(ast.NodeTransformer):
    def __init__(self, path: str, exempt: frozenset[str]) -> None:
        self.path = path
        self.exempt = exempt

    def _where(self, node: ast.expr | ast.stmt) -> ast.Tuple:
        return ast.Tuple(
            [ast.Constant(self.path), ast.Constant(node.lineno), ast.Constant(node.col_offset)],
            ast.Load(),
        )

    def _call(self, name: str, args: list[ast.expr], node: ast.AST) -> ast.Call:
        return ast.copy_location(ast.Call(ast.Name(name, ast.Load()), args, []), node)

    def visit_FunctionDef(self, node: ast.FunctionDef) -> ast.AST:
        if node.name in self.exempt:
            return node  # an audited primitive: left exactly as written
        return self.generic_visit(node)

    def visit_BinOp(self, node: ast.BinOp) -> ast.AST:
        self.generic_visit(node)
        entry = _OPS.get(type(node.op))
        if entry is None:
            return node
        return self._call(
            CHECK_NAME, [self._where(node), ast.Constant(entry[0]), node.left, node.right], node
        )

    def visit_UnaryOp(self, node: ast.UnaryOp) -> ast.AST:
        self.generic_visit(node)
        if not isinstance(node.op, ast.USub):
            return node
        return self._call(NEG_NAME, [self._where(node), node.operand], node)

    def visit_AugAssign(self, node: ast.AugAssign) -> ast.AST:
        binop = ast.copy_location(ast.BinOp(_load_ctx(node.target), node.op, node.value), node)
        assign = ast.copy_location(ast.Assign([node.target], binop), node)
        return self.visit(assign)  # type: ignore[no-any-return]


def instrument(source: str, path: str, exempt: frozenset[str] = frozenset()) -> ast.Module:
    """The module's AST with every checked operation routed through the recorder."""
    tree = _Rewriter(path, exempt).visit(ast.parse(source, filename=path))
    assert isinstance(tree, ast.Module)
    return ast.fix_missing_locations(tree)


def _short_path(origin: str) -> str:
    """``firmware/trig.py`` for any path of a firmware module (through the odocan/ symlink)."""
    return f"firmware/{Path(origin).name}" if Path(origin).parent.name == "firmware" else origin


class _Loader(importlib.abc.Loader):
    def __init__(self, origin: str, recorder: Recorder, fullname: str) -> None:
        self.origin = origin
        self.recorder = recorder
        self.fullname = fullname

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return None

    def exec_module(self, module: ModuleType) -> None:
        source = Path(self.origin).read_text(encoding="utf-8")
        path = _short_path(self.origin)
        exempt = (
            audited_helpers(ast.parse(source)) if self.fullname == FIXMATH_MODULE else frozenset()
        )
        code = compile(instrument(source, path, exempt), self.origin, "exec")
        module.__dict__[CHECK_NAME] = self.recorder.binop
        module.__dict__[NEG_NAME] = self.recorder.neg
        exec(code, module.__dict__)  # the firmware's own source, rewritten


class _Finder(importlib.abc.MetaPathFinder):
    def __init__(self, recorder: Recorder) -> None:
        self.recorder = recorder

    def find_spec(
        self, fullname: str, path: Any = None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if not fullname.startswith(FIRMWARE_PACKAGE + "."):
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None:
                break
        else:
            return None
        if spec.origin is None or not spec.origin.endswith(".py"):
            return spec
        return importlib.util.spec_from_file_location(
            fullname, spec.origin, loader=_Loader(spec.origin, self.recorder, fullname)
        )


def _is_odocan(name: str) -> bool:
    return name == "odocan" or name.startswith("odocan.")


@contextlib.contextmanager
def instrumented_firmware(recorder: Recorder) -> Iterator[None]:
    """Within the block, ``import odocan...`` gives fresh modules over the instrumented firmware.

    Every ``odocan`` module is taken out of ``sys.modules`` on entry (so sim/ and host/ re-import
    and bind the instrumented firmware) and put back exactly as it was on exit, parent packages
    included, so the rest of the test session never sees an instrumented module.
    """
    saved = {name: module for name, module in sys.modules.items() if _is_odocan(name)}
    for name in saved:
        del sys.modules[name]
    finder = _Finder(recorder)
    sys.meta_path.insert(0, finder)
    try:
        yield
    finally:
        sys.meta_path.remove(finder)
        for name in [n for n in sys.modules if _is_odocan(n)]:
            del sys.modules[name]
        sys.modules.update(saved)


# --- the drives --------------------------------------------------------------------------------


class _Unpacker(can.Listener):
    """The host's ears: every frame heard is unpacked (the firmware's own ``unpack_*`` for what
    it receives, so those decoders run instrumented too) and counted by frame id; the ODOM_ACK
    records are kept."""

    def __init__(self) -> None:
        self.fr = importlib.import_module(FIRMWARE_PACKAGE + ".frames")
        received = ["wheel_encoders", "odom_set_pose", "odom_config", "nav_goal", "odom_auth"]
        decoders = {name: getattr(self.fr, f"unpack_{name}") for name in received}
        sim_frames = importlib.import_module("odocan.sim.frames")  # MOTOR_CTRL's: not firmware
        decoders["motor_cmd"] = sim_frames.unpack_motor_cmd
        for name in [  # the host's half (tests/host_frames.py): not firmware, not instrumented
            "odom_pose_x",
            "odom_pose_y",
            "odom_twist",
            "nav_status",
            "odom_ack",
            "odom_freshness",
            "odom_status",
            "sim_truth",
        ]:
            decoders[name] = getattr(hf, f"unpack_{name}")
        self.unpack: dict[int, Callable[[bytes], Any]] = {
            getattr(self.fr, f"{name.upper()}_ID"): decode for name, decode in decoders.items()
        }
        self.heard: dict[int, int] = {}
        self.acks: list[Any] = []
        self.freshness: Any = None  # the last ODOM_FRESHNESS record

    def on_message_received(self, msg: can.Message) -> None:
        record = self.unpack[msg.arbitration_id](bytes(msg.data))
        self.heard[msg.arbitration_id] = self.heard.get(msg.arbitration_id, 0) + 1
        if msg.arbitration_id == self.fr.ODOM_ACK_ID:
            self.acks.append(record)
        elif msg.arbitration_id == self.fr.ODOM_FRESHNESS_ID:
            self.freshness = record


def _lockstep_drives(duration_s: float, ears: _Unpacker) -> None:
    """Random drives of every integrator on both shipped robots, through the whole rig (on pmir
    the motor controller restarted at the end, CTRL_UPTIME going back); on pmir a second round
    with dropped, duplicated and bit-flipped frames (E2E, gaps)."""
    rig_mod = importlib.import_module("odocan.sim.rig")
    robot = importlib.import_module("odocan.sim.robot")
    faults = importlib.import_module("odocan.sim.faults")
    hostile = faults.FaultSpec(drop=0.03, dup=0.03, flip=0.03, seed=5)
    bus_off = faults.FaultSpec(busoff=faults.BusOff(at_s=1.0, duration_s=0.5))
    runs = [("pmir", None, None), ("kobuki", None, None), ("pmir", hostile, bus_off)]
    for index, (robot_name, spec, fw_spec) in enumerate(runs):
        for seed, integrator in enumerate(rig_mod.INTEGRATORS):
            config = rig_mod.RigConfig(
                robot.load(robot_name),
                integrator,
                "random",
                seed=seed,
                channel=f"width_{index}_{integrator}",
                faults=spec,
                fw_faults=fw_spec,
                duration_s=duration_s,
            )
            with contextlib.closing(rig_mod.LockstepRig(config, [ears])) as rig:
                rig.run()
                if index == 0:  # the controller silent 1.5 s (its CTRL_UPTIME ages), then
                    _silence_controller(rig, 1.5)  # it restarts: CTRL_UPTIME goes back
                    rig.motor_controller.restart()
                    rig.run(1.0)
                rig.listeners = []  # closing the rig must not stop the shared listener


def _silence_controller(rig: Any, seconds: float) -> None:
    """Run ``seconds`` with the motor controller's frames lost (its E2E COUNTER goes on, one a
    tick), then 0.5 s of it speaking again: the firmware ages the last CTRL_UPTIME over the
    silence (``_aged_uptime``; a frame that is the E2E successor of the last one, as after a
    silence that lost nothing, is not aged)."""
    send, controller = rig.sim.tick, rig.motor_controller

    def lost(_k: int) -> None:
        controller.counter = (controller.counter + 1) & 0xF

    rig.sim.tick = lost
    rig.run(seconds)
    rig.sim.tick = send
    rig.run(0.5)


def _closed_loop_drive(goal_s: float, ears: _Unpacker) -> None:
    """Navigation, configuration (32-bit counters included), set-pose and E2E on one
    closed-loop rig: the host sends, the firmware drives."""
    fr = importlib.import_module("odocan.firmware.frames")
    errors_mod = importlib.import_module("odocan.firmware.errors")
    rig_mod = importlib.import_module("odocan.sim.rig")
    robot = importlib.import_module("odocan.sim.robot")
    scratch = errors_mod.ErrorMask()
    counters = {fr.NAV_GOAL_ID: 0, fr.ODOM_CONFIG_ID: 0, fr.ODOM_SET_POSE_ID: 0}
    config = rig_mod.RigConfig(robot.load("pmir"), "rk2", None, channel="width_nav")
    with contextlib.closing(rig_mod.LockstepRig(config)) as rig:
        rig.listeners = [ears]

        def send(frame_id: int, pack: Callable[..., bytes], *fields: int) -> None:
            """One host frame, with the next E2E counter of its frame id."""
            counters[frame_id] += 1
            rig.send(frame_id, pack(counters[frame_id] - 1, *fields, scratch))

        def goal(x_m: int, y_m: int, heading_bam16: int, mode: int, goal_id: int) -> None:
            send(fr.NAV_GOAL_ID, hf.pack_nav_goal, fr.NavGoalField.X, x_m)
            send(fr.NAV_GOAL_ID, hf.pack_nav_goal, fr.NavGoalField.Y, y_m)
            send(fr.NAV_GOAL_ID, hf.pack_nav_goal, fr.NavGoalField.HEADING, heading_bam16)
            send(fr.NAV_GOAL_ID, hf.pack_nav_goal_go, mode, 1, 0, goal_id)

        rig.run(0.5)  # odometry running: before that a GO is refused (BUSY)
        goal(6_000, 3_000, 0x4000, fr.NavMode.TURN_GO_TURN, 1)  # 0.6 m, 0.3 m, 90 degrees
        goal(-3_000, -3_000, 0xC000, fr.NavMode.GO_TO_GOAL, 2)
        rig.run(goal_s)
        for param, value in (
            (fr.ConfigParam.WHEEL_RADIUS_LEFT, 75_150_000),
            (fr.ConfigParam.INTEGRATOR, 2),
            (fr.ConfigParam.WHEELBASE, 5),  # out of range: nacked
            (fr.ConfigParam.APPLY, 0),
            (fr.ConfigParam.WHEELBASE, 301_000_000),
            (fr.ConfigParam.COUNTER_BITS, 32),  # the 24-bit wire counts extended on board
            (fr.ConfigParam.APPLY, 0),
        ):
            send(fr.ODOM_CONFIG_ID, hf.pack_odom_config, param, value)
            rig.step()
        for field_id, value in (
            (fr.SetPoseField.X, -2_000_000_000),  # -200 km: far goals, distance shifts
            (fr.SetPoseField.Y, 2_000_000_000),
            (fr.SetPoseField.HEADING, 0x8001),
            (fr.SetPoseField.APPLY, 0),
        ):
            send(fr.ODOM_SET_POSE_ID, hf.pack_odom_set_pose, field_id, value)
            rig.step()
        rig.send(fr.NAV_GOAL_ID, bytes(8))  # a corrupted frame: E2E rejects it
        rig.send(fr.NAV_GOAL_ID, bytes(7))  # a frame of the wrong length
        for _ in range(40):  # more frames in one tick than the mailbox holds
            rig.send(fr.SIM_TRUTH_ID, bytes(8))
        goal(0, 0, 0, fr.NavMode.TURN_GO_TURN, 3)
        rig.run(goal_s / 4)
        send(fr.NAV_GOAL_ID, hf.pack_nav_goal, fr.NavGoalField.STOP, 0)
        rig.run(goal_s / 4)
        rig.listeners = []


def _vector_cases() -> None:
    """The golden vectors' edge cases (wraps, big steps, spin, straight), every integrator."""
    vectors = importlib.import_module("odocan.host.judge.vectors")
    config = importlib.import_module("odocan.firmware.config")
    for integrator in (0, 1, 2):
        for counter_bits in (16, 32):
            params = config.RobotParams(
                500, 75_000_000, 75_100_000, 300_000_000, counter_bits, integrator
            )
            for case in vectors.edge_cases(counter_bits):
                vectors.run_case(params, case)


def _i64_edges() -> list[int]:
    points = [0, 1 << 31, 1 << 32, 1 << 47, 1 << 62, 1 << 63]
    return sorted({sign * p + k for p in points for sign in (1, -1) for k in (-1, 0, 1)})


def _edge_sweep() -> None:
    """The pure functions on the edges of their declared C types (i64, i32, u32 BAM angles):
    widths a drive rarely reaches (I64_MIN, a 2^31-count step, a half-turn step)."""
    fw = {
        name: importlib.import_module(f"{FIRMWARE_PACKAGE}.{name}")
        for name in ("trig", "odometry", "nav", "config", "errors")
    }
    trig, odometry, nav = fw["trig"], fw["odometry"], fw["nav"]
    errors = fw["errors"].ErrorMask()
    i64 = [v for v in _i64_edges() if -(1 << 63) <= v < 1 << 63]
    i32 = [v for v in i64 if -(1 << 31) <= v < 1 << 31]
    for quadrant, knot, offset in itertools.product(range(4), range(0, 257, 8), range(-3, 4)):
        for tie in (0, 1 << 21):
            trig.sincos_q30(((quadrant << 30) + (knot << 22) + tie + offset) & 0xFFFF_FFFF)
    for y, x in itertools.product(i64, repeat=2):
        trig.atan2_bam32(y, x)
        nav.distance_um(x, y, errors)
    for d in i64:
        odometry.chord_factor_q62(d)
    for e in i32:
        nav.go_to_goal_law(1 << 43, e, errors)
        nav.drive_straight_law(1 << 43, e, errors)
        nav.wheel_speeds_mm_s(e, e, 4_000_000_000)
    e2e = importlib.import_module(f"{FIRMWARE_PACKAGE}.e2e")
    data_ids = tuple(range(16))
    receiver = e2e.E2EReceiver(data_ids, max_delta_counter_init=0, window_per_period=True)
    counter = 0
    for jump in (1, 1, 0, 5, 1):  # OK, OK, REPEATED, WRONGSEQUENCE, OK
        counter = hf.p02_next_counter(counter + jump - 1)
        frame = bytearray(8)
        hf.p02_protect(frame, counter, data_ids)
        receiver.check(bytes(frame))
    for integrator, bits in itertools.product(range(3), (16, 32)):
        config = fw["config"]
        # the most travel per count the ranges allow: 2 m wheels, 16 counts per turn
        params = config.RobotParams(16, 2_000_000_000, 1_000_000, 4_000_000_000, bits, integrator)
        assert config.validate(params) == 0, config.validate(params)
        odo = odometry.Odometry(config.derive_constants(params, errors), errors)
        for d_left, d_right in itertools.product(i32, repeat=2):
            odo.step_deltas(d_left, d_right)


class _Nvm:
    """An in-memory NVM cell for the SecOC freshness epoch."""

    def __init__(self, epoch: int = 0, works: bool = True) -> None:
        self.epoch, self.works = epoch, works

    def read_epoch(self) -> int:
        return self.epoch

    def write_epoch(self, epoch: int) -> bool:
        if self.works:
            self.epoch = epoch
        return self.works


def _secoc_drive() -> None:
    """AES-128, CMAC on every tail length, and the SecOC receiver: genuine, forged, replayed,
    out-of-window and post-reboot commands, held commands that authenticate or expire, the
    ODOM_AUTH and ODOM_FRESHNESS codecs, and a receiver that cannot run (bad key, NVM, epoch)."""
    cmac = importlib.import_module(f"{FIRMWARE_PACKAGE}.cmac")
    secoc = importlib.import_module(f"{FIRMWARE_PACKAGE}.secoc")
    key = bytes(range(0x2B, 0x3B))
    mac_key = cmac.cmac_key(key)
    for length in range(0, 49):
        cmac.cmac(mac_key, bytes((7 * k + length) & 0xFF for k in range(length)))
    nvm = _Nvm()
    for mac_bits in (8, 16, 24, 32):
        receiver = secoc.SecocReceiver(key, nvm, mac_bits=mac_bits)
        receiver.boot()
        pdu = bytes(range(8))
        for step in (1, 1, 0, 4096, 4097, 1):
            fv = receiver.last_fv + step
            tag = secoc.truncate(secoc.authenticator(mac_key, 0x300, pdu, fv), mac_bits)
            receiver.verify(0x300, pdu, fv & 0xFFFF, tag)
            receiver.verify(0x300, pdu, fv & 0xFFFF, tag ^ 1)
        receiver.take_sync_cause()
        hf.unpack_odom_freshness(receiver.freshness_frame(4, secoc.FreshnessCause.REFUSED))
        commands = secoc.SecuredCommands(receiver)
        for request in secoc.AuthRequest:
            commands.hold(request, pdu, 10)
            fv = receiver.last_fv + 1
            tag = secoc.truncate(secoc.authenticator(mac_key, 0x300, pdu, fv), 32)
            frame = hf.pack_odom_auth(5, int(request), fv & 0xFFFF, tag)
            commands.authenticate(secoc.unpack_odom_auth(frame))
            commands.hold(request, pdu, 0xFFFF_FFF0)
            commands.expire(0xFFFF_FFFF)
            commands.expire(5)
        commands.authenticate(secoc.OdomAuth(0, 0, 0, 0))  # nothing held: an orphan
    receiver = secoc.SecocReceiver(key, _Nvm(epoch=secoc.EPOCH_MAX))
    receiver.boot()
    broken_nvm = _Nvm(works=False)
    for broken in (secoc.SecocReceiver(key[:15], _Nvm()), secoc.SecocReceiver(key, broken_nvm)):
        broken.boot()
        broken.verify(0x300, bytes(8), 1, 0)
        broken.freshness_frame(0, secoc.FreshnessCause.UNAVAILABLE)


SECOC_KEY = bytes(range(0x40, 0x50))


def _secured_rig_drive(ears: _Unpacker) -> None:
    """The ECU's SecOC paths in a lockstep rig with a key: genuine ODOM_SET_POSE, ODOM_CONFIG and
    NAV_GOAL (signed by the firmware's own authenticator), a forged and a stale one, an unsigned
    one that expires, a displaced hold, an orphan ODOM_AUTH, a reboot (EPOCH 2 from the NVM
    cell) and a board whose NVM refuses writes (AUTH_UNAVAILABLE)."""
    fr = importlib.import_module(f"{FIRMWARE_PACKAGE}.frames")
    secoc = importlib.import_module(f"{FIRMWARE_PACKAGE}.secoc")
    cmac = importlib.import_module(f"{FIRMWARE_PACKAGE}.cmac")
    errors_mod = importlib.import_module(f"{FIRMWARE_PACKAGE}.errors")
    rig_mod = importlib.import_module("odocan.sim.rig")
    robot = importlib.import_module("odocan.sim.robot")
    scratch = errors_mod.ErrorMask()
    mac_key = cmac.cmac_key(SECOC_KEY)
    counters: dict[int, int] = {}
    request = {fr.NAV_GOAL_ID: 0, fr.ODOM_SET_POSE_ID: 1, fr.ODOM_CONFIG_ID: 2}
    config = rig_mod.RigConfig(
        robot.load("pmir"), "exact", None, channel="width_secoc", secoc_key=SECOC_KEY
    )
    with contextlib.closing(rig_mod.LockstepRig(config)) as rig:
        rig.listeners = [ears]
        fv = [0]

        def counter(frame_id: int) -> int:
            counters[frame_id] = (counters.get(frame_id, -1) + 1) & 0xF
            return counters[frame_id]

        def signed(frame_id: int, data: bytes, *, forge: int = 0, stale: bool = False) -> None:
            rig.send(frame_id, data)
            fv[0] += 0 if stale else 1  # stale: the last accepted value again
            tag = secoc.authenticator(mac_key, frame_id, data, fv[0]) ^ forge
            rig.send(
                fr.ODOM_AUTH_ID,
                hf.pack_odom_auth(
                    counter(fr.ODOM_AUTH_ID), request[frame_id], fv[0] & 0xFFFF, tag, scratch
                ),
            )

        def sync() -> None:
            rig.run(0.05)
            fv[0] = ears.freshness.fv

        rig.run(0.5)
        sync()
        for field_id, value in ((fr.SetPoseField.X, 12_345), (fr.SetPoseField.APPLY, 0)):
            pose = hf.pack_odom_set_pose(counter(fr.ODOM_SET_POSE_ID), field_id, value, scratch)
            signed(fr.ODOM_SET_POSE_ID, pose)
            rig.step()
        wheelbase = hf.pack_odom_config(
            counter(fr.ODOM_CONFIG_ID), fr.ConfigParam.WHEELBASE, 301_000_000, scratch
        )
        signed(fr.ODOM_CONFIG_ID, wheelbase)
        goal_x = hf.pack_nav_goal(counter(fr.NAV_GOAL_ID), fr.NavGoalField.X, 1_000, scratch)
        signed(fr.NAV_GOAL_ID, goal_x)
        goal_x = hf.pack_nav_goal(counter(fr.NAV_GOAL_ID), fr.NavGoalField.X, 1_000, scratch)
        signed(fr.NAV_GOAL_ID, goal_x, stale=True)  # a replay: AUTH_FRESHNESS, then a resync
        rig.step()
        sync()

        def goal_y() -> bytes:
            return hf.pack_nav_goal(counter(fr.NAV_GOAL_ID), fr.NavGoalField.Y, 1_000, scratch)

        signed(fr.NAV_GOAL_ID, goal_y(), forge=1)  # AUTH_FAILED
        rig.send(fr.NAV_GOAL_ID, goal_y())  # unsigned and displaced by the next: AUTH_MISSING
        rig.send(fr.NAV_GOAL_ID, goal_y())  # unsigned: AUTH_MISSING after 2 ticks
        rig.send(
            fr.ODOM_AUTH_ID,
            hf.pack_odom_auth(counter(fr.ODOM_AUTH_ID), 1, 0, 0, scratch),  # an orphan
        )
        rig.run(0.1)
        rig.board.reboot()
        sync()
        signed(
            fr.ODOM_SET_POSE_ID,
            hf.pack_odom_set_pose(counter(fr.ODOM_SET_POSE_ID), fr.SetPoseField.APPLY, 0, scratch),
        )
        rig.run(1.1)  # a periodic ODOM_FRESHNESS
        rig.board.nvm.fail_writes = True
        rig.board.reboot()
        rig.send(
            fr.ODOM_SET_POSE_ID,
            hf.pack_odom_set_pose(counter(fr.ODOM_SET_POSE_ID), fr.SetPoseField.APPLY, 0, scratch),
        )
        rig.send(
            fr.ODOM_AUTH_ID,
            hf.pack_odom_auth(counter(fr.ODOM_AUTH_ID), 1, 1, 0, scratch),  # AUTH_UNAVAILABLE
        )
        rig.run(0.1)
        rig.listeners = []


HEALTH_SCENARIOS = "tests.test_health_firmware"  # stalls, overflows, forgeries, restarts, gaps
BURST_SCENARIOS = "tests.test_babble_fast_bus"  # runs the mailbox dropped, a babbler on its ID
FORGED_SCENARIOS = "tests.test_forged_step_gate"  # counts beyond a 16-bit counter's width
BURST_TESTS = (
    "test_after_frames_its_mailbox_dropped_the_twist_is_right_and_every_one_is_counted",
    "test_a_babblers_frames_on_the_encoder_id_are_not_taken_for_dropped_encoder_frames",
    "test_forged_frames_whose_crc_holds_dropped_on_the_encoder_id_are_absorbed",
)


def _call_each_case(test: Callable[..., None]) -> None:
    """Call a test function once per case of its ``pytest.mark.parametrize`` (one such mark at
    most, plain values), or once if it has none."""
    marks = [m for m in getattr(test, "pytestmark", []) if m.name == "parametrize"]
    if not marks:
        test()
        return
    assert len(marks) == 1, f"{test.__name__}: one parametrize mark at most"
    argnames, argvalues = marks[0].args[:2]
    names = [n.strip() for n in argnames.split(",")] if isinstance(argnames, str) else argnames
    for values in argvalues:
        test(**dict(zip(names, values if len(names) > 1 else (values,), strict=True)))


def _health_drive() -> None:
    """The firmware-level health scenarios (lost time, FIFO overrun, mailbox overflow, forged and
    implausible steps, counter restarts and their recovery, twist after 16/31/100-period gaps,
    runs of frames the mailbox dropped, a babbler's frames on the encoder ID, a forged frame
    setting a 16-bit robot's unused wire bits),
    run from a fresh import of their test module so that it binds the instrumented firmware."""
    fresh = (HEALTH_SCENARIOS, BURST_SCENARIOS, FORGED_SCENARIOS, "tests.test_ecu")
    saved = {name: sys.modules.pop(name) for name in fresh if name in sys.modules}
    try:
        scenarios = importlib.import_module(HEALTH_SCENARIOS)
        for name in sorted(dir(scenarios)):
            test = getattr(scenarios, name)
            if name.startswith("test_") and callable(test):
                _call_each_case(test)
        bursts = importlib.import_module(BURST_SCENARIOS)
        for name in BURST_TESTS:
            _call_each_case(getattr(bursts, name))
        forged = importlib.import_module(FORGED_SCENARIOS)  # a 16-bit robot's wire top bits set
        ecu = forged.OdomEcu(forged.RecordingHal(), forged.firmware_params(forged.load("kobuki"),
                                                                           "exact"))
        forged._run(ecu, forged._script(20, (0x3D0000 | 250, 0x3E0000 | 240), flood=False))
        assert ecu.encoders.frames_implausible == 1
        rig = scenarios.TimedRig()
        for _ in range(3):
            rig.step()
        rig.ecu.isr_rx_overrun()  # the board's CAN FIFO overrun interrupt
        encoders = rig.ecu.encoders
        encoders._step_periods(encoders._enc_prev_counter)  # a whole 16-period counter cycle
    finally:
        for name in fresh:
            sys.modules.pop(name, None)
        sys.modules.update(saved)


CLOSED_LOOP_MIN_S = 10.0  # the first two goals are reached (NAV_STATUS REACHED) within it


@dataclass
class DriveLog:
    """What the host heard during the drives (frame id -> count) and the ODOM_ACKs."""

    heard: dict[int, int]
    acks: list[Any]


def standard_drives(recorder: Recorder, duration_s: float = 20.0) -> DriveLog:
    """Every drive above, through the instrumented firmware."""
    with instrumented_firmware(recorder):
        ears = _Unpacker()
        _lockstep_drives(duration_s, ears)
        _closed_loop_drive(max(duration_s, CLOSED_LOOP_MIN_S), ears)
        _vector_cases()
        _edge_sweep()
        _secoc_drive()
        _secured_rig_drive(ears)
        _health_drive()
    return DriveLog(ears.heard, ears.acks)


if __name__ == "__main__":
    found = Recorder()
    standard_drives(found, float(sys.argv[1]) if len(sys.argv) > 1 else 20.0)
    for site in found.report():
        print(site)
    places = firmware_sites()
    missed = sorted(p for p in places if (p.path, p.line, p.col) not in found.seen)
    for place in missed:
        print(f"not reached: {place.path}:{place.line}:{place.col} in {place.function}")
    print(f"{len(found.sites)} site(s), {found.checks} checked operations")
    print(f"{len(places) - len(missed)} of {len(places)} arithmetic places reached")

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
  (reported as ``operand``). A wider operand is not reported again: it is the result of a site
  reported already (or came from outside the firmware), so each wide value is counted once,
  where it is made.
* Not checked: ``& | ^ ~`` (they cannot widen 64-bit operands) and comparisons.
* Exempt: the bodies of the audited primitives, the functions of ``firmware/fixmath.py`` whose
  docstring gives their C form on a line starting with ``C:`` (``audited_helpers``). Their
  arguments are still checked where they are computed, at the call site.

Only integer values are checked (``bytes + bytes`` or a tuple concatenation is not arithmetic).
Run ``python -m tests.width_sanitizer`` to print the sites of the standard drives.
"""

from __future__ import annotations

import ast
import contextlib
import copy
import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import operator
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

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

    def _where(self, node: ast.AST) -> ast.Tuple:
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
    tree = ast.parse(source, filename=path)
    tree = _Rewriter(path, exempt).visit(tree)
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


def _lockstep_drives(duration_s: float) -> None:
    """Random drives of every integrator on both shipped robots, through the whole rig."""
    rig_mod = importlib.import_module("odocan.sim.rig")
    robot = importlib.import_module("odocan.sim.robot")
    for robot_name in ("pmir", "kobuki"):
        for seed, integrator in enumerate(rig_mod.INTEGRATORS):
            config = rig_mod.RigConfig(
                robot.load(robot_name),
                integrator,
                "random",
                seed=seed,
                channel=f"width_{robot_name}_{integrator}",
                duration_s=duration_s,
            )
            with contextlib.closing(rig_mod.LockstepRig(config)) as rig:
                rig.run()


def _closed_loop_drive(goal_s: float) -> None:
    """Navigation, configuration, set-pose and E2E on one closed-loop rig (the host sends)."""
    fr = importlib.import_module("odocan.firmware.frames")
    errors_mod = importlib.import_module("odocan.firmware.errors")
    rig_mod = importlib.import_module("odocan.sim.rig")
    robot = importlib.import_module("odocan.sim.robot")
    scratch = errors_mod.ErrorMask()
    counters = {fr.NAV_GOAL_ID: 0, fr.ODOM_CONFIG_ID: 0, fr.ODOM_SET_POSE_ID: 0}
    config = rig_mod.RigConfig(robot.load("pmir"), "rk2", None, channel="width_nav")
    with contextlib.closing(rig_mod.LockstepRig(config)) as rig:

        def send(frame_id: int, pack: Callable[..., bytes], *fields: int) -> None:
            """One host frame, with the next E2E counter of its frame id."""
            counters[frame_id] += 1
            rig.send(frame_id, pack(counters[frame_id] - 1, *fields, scratch))

        def goal(x_m: int, y_m: int, heading_bam16: int, mode: int, goal_id: int) -> None:
            send(fr.NAV_GOAL_ID, fr.pack_nav_goal, fr.NavGoalField.X, x_m)
            send(fr.NAV_GOAL_ID, fr.pack_nav_goal, fr.NavGoalField.Y, y_m)
            send(fr.NAV_GOAL_ID, fr.pack_nav_goal, fr.NavGoalField.HEADING, heading_bam16)
            send(fr.NAV_GOAL_ID, fr.pack_nav_goal_go, mode, 1, 0, goal_id)

        goal(10_000, 5_000, 0x4000, fr.NavMode.TURN_GO_TURN, 1)  # 1 m, 0.5 m, 90 degrees
        goal(-5_000, -5_000, 0xC000, fr.NavMode.GO_TO_GOAL, 2)
        rig.run(goal_s)
        for param, value in (
            (fr.ConfigParam.WHEEL_RADIUS_LEFT, 75_150_000),
            (fr.ConfigParam.INTEGRATOR, 2),
            (fr.ConfigParam.WHEELBASE, 5),  # out of range: nacked
            (fr.ConfigParam.APPLY, 0),
            (fr.ConfigParam.WHEELBASE, 301_000_000),
            (fr.ConfigParam.APPLY, 0),
        ):
            send(fr.ODOM_CONFIG_ID, fr.pack_odom_config, param, value)
            rig.step()
        for field_id, value in (
            (fr.SetPoseField.X, -2_000_000_000),
            (fr.SetPoseField.Y, 2_000_000_000),
            (fr.SetPoseField.HEADING, 0x8001),
            (fr.SetPoseField.APPLY, 0),
        ):
            send(fr.ODOM_SET_POSE_ID, fr.pack_odom_set_pose, field_id, value)
            rig.step()
        rig.send(fr.NAV_GOAL_ID, bytes(8))  # a corrupted frame: E2E rejects it
        goal(0, 0, 0, fr.NavMode.TURN_GO_TURN, 3)
        rig.run(goal_s)


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


def standard_drives(recorder: Recorder, duration_s: float = 20.0) -> None:
    """Every drive above, through the instrumented firmware."""
    with instrumented_firmware(recorder):
        _lockstep_drives(duration_s)
        _closed_loop_drive(duration_s)
        _vector_cases()


if __name__ == "__main__":
    found = Recorder()
    standard_drives(found, float(sys.argv[1]) if len(sys.argv) > 1 else 20.0)
    for site in found.report():
        print(site)
    print(f"{len(found.sites)} site(s), {found.checks} checked operations")

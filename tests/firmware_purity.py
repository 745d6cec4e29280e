"""The AST scan that keeps firmware/ integer-only and standard-library-only (house rule 1)."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

FIRMWARE_DIR = Path(__file__).resolve().parent.parent / "firmware"
ALLOWED_IMPORTS = frozenset(
    {
        "__future__",
        "typing",
        "dataclasses",
        "enum",
        "struct",
        "collections",
        "abc",
        "functools",
        "itertools",
        "array",
    }
)
FIRMWARE_PACKAGE = "odocan.firmware"
FORBIDDEN_CALLS = frozenset({"float", "round", "complex", "eval", "exec", "__import__"})


@dataclass(frozen=True)
class Violation:
    """One forbidden construct, where it is."""

    path: str
    line: int
    what: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.what}"


class _Scanner(ast.NodeVisitor):
    def __init__(self, path: str) -> None:
        self.path = path
        self.found: list[Violation] = []

    def _flag(self, node: ast.AST, what: str) -> None:
        self.found.append(Violation(self.path, getattr(node, "lineno", 0), what))

    def visit_Constant(self, node: ast.Constant) -> None:
        if isinstance(node.value, float | complex):
            self._flag(node, f"float literal {node.value!r}")

    def visit_BinOp(self, node: ast.BinOp) -> None:
        if isinstance(node.op, ast.Div):
            self._flag(node, "true division '/'")
        if isinstance(node.op, ast.Pow) and _is_negative_constant(node.right):
            self._flag(node, "'**' with a negative exponent (a float)")
        self.generic_visit(node)

    def visit_AugAssign(self, node: ast.AugAssign) -> None:
        if isinstance(node.op, ast.Div):
            self._flag(node, "true division '/='")
        self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> None:
        if isinstance(node.func, ast.Name) and node.func.id in FORBIDDEN_CALLS:
            self._flag(node, f"call of {node.func.id}()")
        self.generic_visit(node)

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            self._check_module(node, alias.name)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.level == 0 and node.module is not None:
            self._check_module(node, node.module)

    def _check_module(self, node: ast.AST, module: str) -> None:
        own = module == FIRMWARE_PACKAGE or module.startswith(FIRMWARE_PACKAGE + ".")
        if not own and module.split(".")[0] not in ALLOWED_IMPORTS:
            self._flag(node, f"import of {module!r} (not standard-library-allowed nor firmware)")


def _is_negative_constant(node: ast.expr) -> bool:
    return (
        isinstance(node, ast.UnaryOp)
        and isinstance(node.op, ast.USub)
        and isinstance(node.operand, ast.Constant)
    )


def scan_source(source: str, path: str = "<string>") -> list[Violation]:
    """Every forbidden construct in one module's source."""
    scanner = _Scanner(path)
    scanner.visit(ast.parse(source, filename=path))
    return scanner.found


def scan_firmware(root: Path = FIRMWARE_DIR) -> list[Violation]:
    """Every forbidden construct in every module under firmware/."""
    found: list[Violation] = []
    for module in sorted(root.rglob("*.py")):
        found += scan_source(
            module.read_text(encoding="utf-8"), str(module.relative_to(root.parent))
        )
    return found


if __name__ == "__main__":
    violations = scan_firmware()
    for v in violations:
        print(v)
    print(f"{len(violations)} violation(s) in {FIRMWARE_DIR}")

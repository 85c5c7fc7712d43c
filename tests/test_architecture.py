"""The package's import rules (docs/ARCHITECTURE.md), checked on the source with ``ast``.

Every module of ``physgnn`` belongs to one part; a part may import only the parts below it
(:data:`ALLOWED`). Also: no import loop between modules, every project import at the top of
its module, no command module (``python -m physgnn.X``) imported by another module, the
physics side free of the network, Lightning and Hydra, the network free of Lightning and
Hydra, and modules and functions of a readable size.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "physgnn"
COMMANDS = {
    "train",
    "generate",
    "eval",
    "bench",
    "data_report",
    "sleep_study",
    "simulate",
    "study",
    "ship",
}

# part -> the parts it may import (besides itself). "base" is physgnn/__init__, errors, files,
# locks, ranges, overrides.
ALLOWED = {
    "base": set(),
    "cli": {"base"},
    "physics": {"base"},
    "data": {"physics", "base"},
    "graph": {"data", "physics", "base"},
    "nn": set(),
    "metrics": {"graph", "physics", "base"},
    "groundtruth": {"data", "physics", "base"},
    "models": {"nn", "graph", "data", "physics", "base"},
    "rollout": {"models", "data", "physics", "base"},
    "report": {"metrics", "physics", "base"},
    "training": {"rollout", "metrics", "models", "data", "physics", "base"},
    "evaluation": {
        "training",
        "report",
        "rollout",
        "metrics",
        "models",
        "groundtruth",
        "data",
        "physics",
        "base",
    },
    "benchmark": {
        "training",
        "report",
        "rollout",
        "metrics",
        "models",
        "groundtruth",
        "data",
        "physics",
        "base",
    },
    "ablation": {
        "cli",
        "evaluation",
        "training",
        "report",
        "rollout",
        "metrics",
        "models",
        "groundtruth",
        "data",
        "physics",
        "benchmark",
        "base",
    },
    "commands": {"cli", "training", "groundtruth", "evaluation", "benchmark", "ablation"},
    # the notebook API: what a notebook needs, from evaluation down
    "api": {
        "evaluation",
        "training",
        "rollout",
        "metrics",
        "models",
        "groundtruth",
        "data",
        "physics",
        "base",
    },
    # the console script imports each command by name when it runs it
    "__main__": set(),
}
# Outside libraries a part must not import (prefixes of module names).
FORBIDDEN = {
    "physics": ("lightning", "hydra", "omegaconf", "torch_geometric", "physgnn.nn"),
    "data": ("lightning", "hydra", "torch_geometric.nn"),
    "graph": ("lightning", "hydra", "omegaconf", "torch_geometric.nn"),
    "metrics": ("lightning", "hydra", "omegaconf", "torch_geometric.nn"),
    "groundtruth": ("lightning", "hydra", "torch_geometric.nn", "physgnn.nn"),
    "nn": ("lightning", "hydra", "omegaconf"),
    "models": ("lightning", "hydra", "omegaconf"),
    "rollout": ("lightning", "hydra", "omegaconf"),
    "report": ("lightning", "hydra", "torch"),
}
# A module holds one meaning (docs/ARCHITECTURE.md, rule 6): one past 300 lines holds several
# and is split by meaning, never squeezed under the cap with `# fmt: skip` lines.
MAX_MODULE_LINES = 300
MAX_FUNCTION_LINES = 50
# arguments of a function or constructor (self and cls not counted): past this, a group of them
# belongs together in a small typed node (models/options.py, training/recipe.py, RolloutBounds)
MAX_ARGUMENTS = 10


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def part_of(module: str) -> str:
    rest = module.split(".")[1:]
    if not rest or rest[0] in ("errors", "files", "locks", "ranges", "overrides"):
        return "base"
    if rest[0] in COMMANDS and len(rest) == 1:
        return "commands"
    return rest[0]


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}
TREES = {name: ast.parse(path.read_text()) for name, path in MODULES.items()}


def imports(tree: ast.AST, module: str) -> list[tuple[str, ast.AST]]:
    """Every module imported anywhere in ``tree`` (``from a import b`` gives ``a.b`` when
    that is a module, else ``a``), with its node."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(alias.name, node) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import
                base = ".".join(module.split(".")[: -node.level] + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                out.append((sub if sub in MODULES else base, node))
    return out


def project_imports(module: str) -> set[str]:
    return {m for m, _ in imports(TREES[module], module) if m in MODULES and m != module}


def test_every_part_imports_only_the_parts_below_it():
    wrong = []
    for module in MODULES:
        part = part_of(module)
        for target in project_imports(module):
            other = part_of(target)
            if other != part and other not in ALLOWED[part]:
                wrong.append(f"{module} ({part}) imports {target} ({other})")
    assert not wrong, "\n".join(wrong)


def test_the_allowed_part_graph_has_no_cycle():
    done: set[str] = set()

    def visit(part, path):
        assert part not in path, f"cycle of parts: {' -> '.join([*path, part])}"
        if part in done:
            return
        for below in ALLOWED[part]:
            visit(below, [*path, part])
        done.add(part)

    for part in ALLOWED:
        visit(part, [])


def test_no_import_loop_between_modules():
    state: dict[str, str] = {}

    def visit(module, path):
        if state.get(module) == "open":
            loop = path[path.index(module) :] + [module]
            pytest.fail("import loop: " + " -> ".join(loop))
        if state.get(module) == "done":
            return
        state[module] = "open"
        for target in sorted(project_imports(module)):
            visit(target, [*path, module])
        state[module] = "done"

    for module in MODULES:
        visit(module, [])


def test_project_imports_are_at_the_top_of_their_module():
    nested = []
    for module, tree in TREES.items():
        top = set(map(id, tree.body))
        for name, node in imports(tree, module):
            if name.startswith("physgnn") and id(node) not in top:
                nested.append(f"{module}:{node.lineno} imports {name} inside a block")
    assert not nested, "\n".join(nested)


def test_no_command_module_is_imported_by_another_module():
    commands = {f"physgnn.{c}" for c in COMMANDS}
    assert commands <= set(MODULES)
    wrong = [f"{m} imports {t}" for m in MODULES for t in project_imports(m) if t in commands]
    assert not wrong, "\n".join(wrong)


def test_command_modules_are_thin_wrappers_of_one_function():
    for command in COMMANDS:
        module = f"physgnn.{command}"
        assert len(MODULES[module].read_text().splitlines()) <= 25, module
        assert "physgnn.cli" in project_imports(module), f"{module} does not use physgnn.cli"


def named_modules(tree: ast.AST) -> list[str]:
    """The project modules a module names in a string (``"physgnn.training.train:val_loss"``,
    or ``"physgnn.groundtruth.generate"`` joined to its function in an f-string): the work
    :func:`physgnn.cli.resolve` imports when a command runs."""
    return [
        node.value.partition(":")[0]
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and re.fullmatch(r"physgnn(\.\w+)+(:\w+)?", node.value)
    ]


def test_the_work_a_command_names_is_of_a_part_it_may_use():
    """A command module imports its work by name once its command line composes (rule 3 would
    have it at the top, and a typo would wait for torch_geometric): the names obey rules 1
    and 4 as an import would."""
    wrong, named = [], 0
    for command in sorted(COMMANDS):
        for target in named_modules(TREES[f"physgnn.{command}"]):
            named += 1
            if target not in MODULES:
                wrong.append(f"physgnn.{command} names {target}, no module")
            elif part_of(target) not in ALLOWED["commands"]:
                wrong.append(f"physgnn.{command} names {target} ({part_of(target)})")
    assert not wrong, "\n".join(wrong)
    assert named >= len(COMMANDS)


def test_every_hydra_main_is_made_by_the_cli_wrapper():
    users = [m for m in MODULES for name, _ in imports(TREES[m], m) if name == "hydra"]
    assert users == ["physgnn.cli"]


def test_forbidden_libraries_stay_out_of_their_parts():
    wrong = []
    for module, tree in TREES.items():
        for name, _ in imports(tree, module):
            for prefix in FORBIDDEN.get(part_of(module), ()):
                if name == prefix or name.startswith(prefix + "."):
                    wrong.append(f"{module} imports {name}")
    assert not wrong, "\n".join(wrong)


def test_only_training_and_the_bench_import_lightning():
    users = {
        part_of(m)
        for m in MODULES
        for name, _ in imports(TREES[m], m)
        if name.startswith("lightning")
    }
    assert users <= {"training", "benchmark"}


def test_modules_and_functions_are_of_a_readable_size_and_take_few_arguments():
    long = []
    for module, path in MODULES.items():
        lines = len(path.read_text().splitlines())
        if lines > MAX_MODULE_LINES:
            long.append(f"{module}: {lines} lines")
        for node in ast.walk(TREES[module]):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                size = node.end_lineno - node.lineno + 1
                if size > MAX_FUNCTION_LINES:
                    long.append(f"{module}.{node.name}: {size} lines")
                if arguments(node) > MAX_ARGUMENTS:
                    long.append(f"{module}.{node.name}: {arguments(node)} arguments")
    assert not long, "\n".join(long)


def arguments(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """How many arguments a caller may pass (``self`` and ``cls`` not counted; ``*args`` and
    ``**kwargs`` count one each)."""
    args = node.args
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return len([n for n in names if n not in ("self", "cls")])


def reads_from_the_working_dir(node: ast.AST) -> bool:
    """``OmegaConf.load("conf/...")``, ``Path("conf")``, ``open("conf/...")``, and Hydra's
    ``initialize(config_path=...)`` (relative paths; ``initialize_config_dir(CONF_DIR)``
    is the way)."""
    if not isinstance(node, ast.Call):
        return False
    if getattr(node.func, "id", "") == "initialize":
        return any(k.arg == "config_path" for k in node.keywords) or bool(node.args)
    if not node.args:
        return False
    func = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
    first = node.args[0]
    return (
        func in {"load", "Path", "open"}
        and isinstance(first, ast.Constant)
        and str(first.value).split("/")[0] == "conf"
    )


def test_no_test_module_imports_another_and_configs_come_from_conf_dir():
    """Helpers shared by test modules live in modules that are not test modules (conftest.py,
    simdata.py, ...), and configs are read from ``physgnn.CONF_DIR``, whatever the working
    directory."""
    wrong = []
    for path in sorted(PACKAGE.parent.joinpath("tests").glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            wrong += [
                f"{path.name} imports {n}"
                for n in names
                if n.rpartition(".")[2].startswith("test_")  # test_x or tests.test_x
            ]
            if reads_from_the_working_dir(node):
                wrong.append(f"{path.name}:{node.lineno} reads conf/ from the working directory")
    assert not wrong, "\n".join(wrong)

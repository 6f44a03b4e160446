"""The pirl.advice package: public names, cheap import, no dependency on the world or env."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pirl.advice

# The modules of the advice core (oracle.py reads the world on purpose and is not imported here).
CORE = [
    "__init__",
    "base",
    "budget",
    "cache",
    "decoding",
    "grammar",
    "local",
    "model_store",
    "openai_advisor",
    "parser",
    "prompt",
    "recommendation",
]


def test_public_names() -> None:
    for name in pirl.advice.__all__:
        assert getattr(pirl.advice, name) is not None
    assert pirl.advice.LocalAdvisor.__name__ == "LocalAdvisor"
    assert pirl.advice.OpenAIAdvisor.__name__ == "OpenAIAdvisor"
    assert "LocalAdvisor" in dir(pirl.advice)


def test_import_is_cheap_and_pure() -> None:
    code = (
        "import sys, json, pirl.advice; "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('torch', 'transformers', 'openai') or m.startswith(('pirl.env', 'pirl.world')))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == []


def test_core_modules_import_nothing_else_from_pirl() -> None:
    folder = Path(pirl.advice.__file__).parent
    for name in CORE:
        tree = ast.parse((folder / f"{name}.py").read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module:
                module = node.module
            elif isinstance(node, ast.Import):
                module = node.names[0].name
            else:
                continue
            if module.startswith("pirl"):
                # The layers below the world (the action grid, the cache folder) are allowed.
                allowed = ("pirl.advice", "pirl.config", "pirl._paths")
                assert module.startswith(allowed), f"{name}.py imports {module}"

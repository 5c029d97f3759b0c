"""The tools' entry points: pyproject.toml's console scripts and the wrappers in bin/.

Each tool is a module motiongan_jax/cli/NAME.py; pyproject.toml installs it as `motiongan-NAME`
(- for _) and bin/NAME.py imports its main. Both only name the module in text, so a renamed
module or a typo would otherwise show only when someone runs the tool.
"""

import ast
import importlib
import pkgutil
import subprocess
import sys
import tomllib

import motiongan_jax.cli

TOOLS = sorted(m.name for m in pkgutil.iter_modules(motiongan_jax.cli.__path__))


def test_every_console_script_resolves_to_a_callable(repo):
    scripts = tomllib.loads((repo / "pyproject.toml").read_text())["project"]["scripts"]
    for name, target in scripts.items():
        module, _, attr = target.partition(":")
        assert attr, f"{name} = {target!r} names no function"
        assert callable(getattr(importlib.import_module(module), attr, None)), f"{name} = {target!r}"
    # every tool is installed, under its own name
    expected = {f"motiongan-{t.replace('_', '-')}": f"motiongan_jax.cli.{t}:main" for t in TOOLS}
    assert {name: scripts.get(name) for name in expected} == expected
    assert "motiongan-demo" in scripts


def test_every_bin_wrapper_only_calls_its_tool(repo):
    wrappers = sorted((repo / "bin").glob("*.py"))
    assert [p.stem for p in wrappers] == TOOLS
    for path in wrappers:
        body = ast.parse(path.read_text()).body
        # a docstring, the import, `raise SystemExit(main())`: no path set-up, no logic of its own
        assert [type(node).__name__ for node in body] == ["Expr", "ImportFrom", "Raise"], path.name
        imp = body[1]
        assert imp.module == f"motiongan_jax.cli.{path.stem}" and [a.name for a in imp.names] == ["main"], path.name
        assert callable(importlib.import_module(imp.module).main)
        assert ast.unparse(body[2]) == "raise SystemExit(main())", path.name


def test_a_wrapper_runs_from_another_directory(repo, tmp_path):
    """bin/X.py finds the package as installed, not through the checkout it sits in."""
    res = subprocess.run([sys.executable, str(repo / "bin" / "plot_metrics.py"), "--help"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    doc = importlib.import_module("motiongan_jax.cli.plot_metrics").__doc__
    assert res.stdout.startswith("usage: plot_metrics.py") and doc.splitlines()[0] in res.stdout

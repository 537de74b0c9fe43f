"""README.md's code runs as pasted: every ```python block, in order, in one fresh
interpreter started in a directory where the repository's ``scenes/`` is reachable (the
README's paths are relative to the repository root), and every ```text block that follows
a Python block is what that code printed."""

import importlib.util
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def readme_blocks(text: str) -> list[tuple[str, str]]:
    """(language, code) of each fenced block of ``text``, in order."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(text)]


def script_of(blocks) -> tuple[str, list[tuple[int, str]]]:
    """One script running the Python blocks in order, each announced by a marker line,
    and the ``text`` blocks each expected after Python block ``i``."""
    lines, expected, n = [], [], -1
    for lang, code in blocks:
        if lang == "python":
            n += 1
            lines.append(f"print('@@block {n}', flush=True)")
            lines.append(code)
        elif lang == "text" and n >= 0:
            expected.append((n, code))
    return "\n".join(lines), expected


def output_of_block(stdout: str, n: int) -> str:
    part = stdout.split(f"@@block {n}\n", 1)[1]
    return part.split("@@block ", 1)[0]


def test_readme_blocks_are_found():
    blocks = readme_blocks("a\n```python\nx = 1\n```\n\n```text\n1\n```\n```sh\nls\n```\n")
    assert blocks == [("python", "x = 1\n"), ("text", "1\n"), ("sh", "ls\n")]
    script, expected = script_of(blocks)
    assert "x = 1" in script and expected == [(0, "1\n")]


def without_optional(blocks, module: str, marker: str):
    """``blocks`` less each Python block that uses ``marker`` (and the text block after
    it) when ``module``, an optional dependency, is not installed (e.g. Dask on the lent
    GPU machines, which have no package registry)."""
    if importlib.util.find_spec(module) is not None:
        return blocks
    kept, dropped = [], False
    for lang, code in blocks:
        if lang == "python":
            dropped = marker in code
        if not (dropped and lang in ("python", "text")):
            kept.append((lang, code))
    return kept


def test_optional_blocks_are_dropped_only_without_their_module():
    blocks = [("python", "import pbr.distributed\n"), ("text", "1\n"), ("python", "x = 1\n")]
    assert without_optional(blocks, "no_such_module_here", "pbr.distributed") == [("python", "x = 1\n")]
    assert without_optional(blocks, "os", "pbr.distributed") == blocks


def _shows(readme_line: str, printed: str) -> bool:
    """Whether a README line is what was printed: the whole line, or its start when the
    README cuts it with '...'."""
    if readme_line.endswith("..."):
        return printed.startswith(readme_line[:-3])
    return printed.rstrip() == readme_line.rstrip()


def test_readme_output_lines_are_whole():
    """A README line that leaves out the end of what was printed must say so with '...'
    (the README once showed the 'valeu' error without its '(did you mean ...?)')."""
    assert _shows("a: b", "a: b") and _shows("a: ...", "a: b (c)")
    assert not _shows("a: b", "a: b (c)")


def test_readme_python_blocks_run(tmp_path):
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        blocks = without_optional(readme_blocks(f.read()), "distributed", "from pbr import distributed")
    script, expected = script_of(blocks)
    assert sum(lang == "python" for lang, _ in blocks) >= 4 and expected
    os.symlink(os.path.join(ROOT, "scenes"), tmp_path / "scenes")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [os.path.join(ROOT, "src")] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path,
                         env=env, timeout=600)
    assert out.returncode == 0, f"README code failed:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    assert (tmp_path / "out.exr").exists()
    for n, text in expected:
        printed = output_of_block(out.stdout, n).splitlines()
        for line in text.splitlines():
            assert any(_shows(line, p) for p in printed), (
                f"README says block {n} prints {line!r}; it printed:\n" + "\n".join(printed))


def test_newcomer_install_notes():
    """Issue 16 item 6: the 'notebooks' extra installs Jupyter (``make notebooks`` installs
    it and opens notebooks/), and the README says that the import name ``pbr`` is shared
    with OpenStack's build tool and how to tell which one is installed."""
    import tomllib
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        extras = tomllib.load(f)["project"]["optional-dependencies"]
    assert any(r.startswith("jupyterlab") for r in extras["notebooks"])
    make = open(os.path.join(ROOT, "Makefile"), encoding="utf-8").read()
    target = make.split("\nnotebooks:", 1)[1].split("\n\n", 1)[0]
    assert re.search(r"pip install .*\[[^\]]*notebooks[^\]]*\]", target) and "jupyter lab notebooks" in target
    readme = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    assert "make notebooks" in readme
    note = readme.split("**The name `pbr`.**", 1)[1].split("\n\n", 1)[0]
    assert "OpenStack" in note and "pbr.__file__" in note and "pip uninstall pbr" in note


def test_readme_command_lines_parse():
    """Every ``pbr ...`` line of the README's shell blocks is accepted by pbr's command-line
    parser (as pasted, less the comment), and gives no option twice (the README once set
    the sample count twice on one line)."""
    import shlex
    from pbr import cli
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        lines = [ln.split("#", 1)[0].strip() for lang, code in readme_blocks(f.read()) if lang == "sh"
                 for ln in code.splitlines()]
    commands = [shlex.split(ln)[1:] for ln in lines if ln.startswith("pbr ")]
    assert len(commands) >= 6
    parser = cli.build_parser()
    for args in commands:
        options = [a.split("=")[0] for a in args if a.startswith("--")]
        assert len(options) == len(set(options)), args
        if args == ["--version"]:
            continue
        parser.parse_args(args)          # exits (SystemExit 2) on an unknown option or a bad value

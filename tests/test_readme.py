"""The jobs block of docs/cli.md ("The jobs, one verb each", linked from the README) runs
in order from an empty folder as written.

Fast: every line parses with the real parser, every file a line reads is made by an
earlier line, the study config example reads those files, and the first lines (the
simulations and the chain) run. Slow (``-m slow``): the whole block, in order."""
import re
import shlex
from pathlib import Path

import pytest

from mdaug.cli import build_parser, main
from mdaug.cli.common import UsageError

README = Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def jobs_block() -> list[list[str]]:
    """The command lines of the README's jobs block (comments dropped), as argv lists."""
    text = README.read_text()
    block = re.search(r"<!-- jobs:begin -->\s*```bash\n(.*?)```\s*<!-- jobs:end -->", text, re.S)
    assert block, "the README's jobs block (between the jobs:begin/end markers) is missing"
    lines = [ln.strip() for ln in block.group(1).splitlines()]
    return [shlex.split(ln) for ln in lines if ln and not ln.startswith("#")]


def study_toml() -> str:
    return re.search(r"```toml\n(.*?)```", README.read_text(), re.S).group(1)


def _files(args, dests) -> list[str]:
    out = []
    for dest in dests:
        v = getattr(args, dest, None)
        items = v if isinstance(v, list) else [v]
        for item in items:
            if isinstance(item, tuple):  # CLASS=FILE
                item = item[1]
            if item is not None:
                out.append(str(item))
    return out


INPUTS = ("measured", "raw", "data", "model", "test", "select", "fit", "posterior", "config")
OUTPUTS = ("out", "out_set", "plot", "corner", "trace", "json")


def test_every_line_parses_and_reads_only_files_made_before_it():
    made, lines = set(), jobs_block()
    verbs = [argv[1] for argv in lines]
    assert all(argv[0] == "mdaug" for argv in lines)
    for v in ("simulate", "process", "calibrate", "augment", "train", "evaluate", "sweep", "baseline", "run"):
        assert v in verbs, f"the README's block never shows mdaug {v}"
    for argv in lines:
        args = build_parser(full={argv[1]}).parse_args(argv[1:])
        for path in _files(args, [d for d in INPUTS if not (d == "model" and argv[1] == "train")]):
            assert path in made, f"{' '.join(argv)}: reads {path}, which no earlier line makes"
        made.update(_files(args, OUTPUTS))
    assert {"old.npz", "new.npz", "more.npz"} <= made
    for name in re.findall(r'"([^"]+\.npz)"', study_toml()):  # the config example reads files of the block
        assert name in made, f"the study config example reads {name}, which the block does not make"


def test_the_first_lines_run_and_the_config_example_reads_their_files(tmp_path, monkeypatch, capsys):
    from mdaug.reports.config import load_config

    monkeypatch.chdir(tmp_path)
    lines = jobs_block()
    first = [argv for argv in lines if argv[1] in ("simulate", "process")]
    assert lines[:len(first)] == first  # the block starts with them
    for argv in first:
        assert main(argv[1:]) == 0, argv
    assert {"old.npz", "more.npz", "new.npz", "processed.npz"} <= {p.name for p in tmp_path.iterdir()}
    (tmp_path / "study.toml").write_text(study_toml())
    cfg = load_config(tmp_path / "study.toml")
    cfg.validate()  # reads every file the example names
    assert not cfg.simulated


@pytest.mark.slow
def test_the_whole_block_runs_in_order_from_an_empty_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for argv in jobs_block():
        assert main(argv[1:]) == 0, " ".join(argv)
    for name in ("old.npz", "new.npz", "post_heli.nc", "post_quad.nc", "post.npz", "cnn.zip", "m.json",
                 "sweep/sweep.md", "tsaug_cnn.zip", "tsaug.npz", "study/report.html"):
        assert (tmp_path / name).is_file(), name


PLACEHOLDERS = {"C", "K", "N", "F", "J", "S", "P", "R", "DIR", "CLASS", "FILE", "ID", "WORK", "OUT"}


def quoted_command_lines() -> list[tuple[str, str]]:
    """(file, line) of every whole ``mdaug`` command the README and docs/ quote: a code
    line, or a code span of the verb and three words or more (shorter spans name a verb
    or an option in prose); those with placeholders (``...``, ``[--x N]``, DIR, K) are
    left out."""
    root = README.parents[1]
    found = []
    for doc in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        text = doc.read_text()
        spans = [ln for ln in re.findall(r"`(mdaug [^`\n]+)`", text) if len(shlex.split(ln)) >= 5]
        for line in spans + re.findall(r"^\s*(mdaug \S.*)$", text, re.M):
            line = line.split("  #")[0].strip()
            words = {w.split("=")[0].split("/")[0] for w in shlex.split(line)}
            if "..." in line or "[" in line or words & PLACEHOLDERS:
                continue
            found.append((doc.name, line))
    return sorted(set(found))


def test_every_command_line_the_docs_quote_parses():
    """A renamed or dropped option is caught wherever the docs still quote it."""
    lines = quoted_command_lines()
    assert len(lines) >= 20 and any(doc == "calibration.md" for doc, _ in lines)
    parser = build_parser()
    bad = []
    for doc, line in lines:
        try:
            parser.parse_args(shlex.split(line)[1:])
        except (SystemExit, UsageError) as exc:
            bad.append(f"{doc}: {line}: {exc}")
    assert not bad, bad

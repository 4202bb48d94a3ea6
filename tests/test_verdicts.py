"""``filter --verdicts FILE``: step B's verdicts written as they come, one JSON line per
composition, and resumed after an interruption with the same final output as an uninterrupted
run (CPU and wall seconds aside: they are measured, not computed)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

from modular_robots.cli import main

from .helpers.runs import hold, signal_stopped, wait_for

ROOT = Path(__file__).resolve().parents[1]
SMALL = ROOT / "tests" / "data" / "small.yaml"
PAPER_5KG = ROOT / "scenarios" / "paper-5kg.yaml"
CLI = [str(Path(sys.executable).parent / "modular-robots")]


def _lines(path: Path) -> list[dict]:
    """The file's lines without their measured seconds."""
    lines = [json.loads(text) for text in path.read_text().splitlines()]
    for line in lines:
        line.pop("seconds", None)
    return lines


def _summary(path: Path) -> dict:
    """``--out``'s document without its measured seconds."""
    document = json.loads(path.read_text())
    del document["cpu_seconds"], document["wall_seconds"]
    return document


def _filter(*arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, "filter", *arguments], cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_an_interrupted_filter_resumes_to_the_output_of_an_uninterrupted_one(tmp_path):
    common = [str(PAPER_5KG), "--jobs", "1", "--limit", "1500"]
    whole = _filter(*common, "--verdicts", str(tmp_path / "whole.jsonl"), "--out", str(tmp_path / "whole.json"))
    assert whole.returncode == 0, whole.stderr

    verdicts = tmp_path / "cut.jsonl"
    child = subprocess.Popen([*CLI, "filter", *common, "--verdicts", str(verdicts)], cwd=ROOT, stderr=subprocess.PIPE)

    def lines() -> int:  # the header and a line per verdict
        return verdicts.read_bytes().count(b"\n")

    # Ctrl-C once 300 verdicts are written, the filter stopped (SIGSTOP) still well short of its
    # 1500 (each line is flushed: the file is what it has done): the signal lands in step B,
    # however busy the machine, instead of after a filter that finished while the test waited.
    wait_for(child, lambda: lines() > 300, "300 verdicts are written")
    hold(child, lambda: lines() - 1 < 1400, "the filter is still in step B, 100 verdicts or more to go")
    signal_stopped(child, signal.SIGINT)
    child.communicate(timeout=300)
    assert child.returncode == 130
    done = verdicts.read_bytes().count(b"\n") - 1
    assert 300 <= done < 1500  # it was interrupted part-way

    resumed = _filter(*common, "--verdicts", str(verdicts), "--out", str(tmp_path / "resumed.json"))
    assert resumed.returncode == 0, resumed.stderr
    assert f"{done} verdict(s) read back from {verdicts}" in resumed.stdout
    assert _lines(verdicts) == _lines(tmp_path / "whole.jsonl")
    assert len(_lines(verdicts)) == 1501
    assert _summary(tmp_path / "resumed.json") == _summary(tmp_path / "whole.json")


def _invoke(*arguments: str):
    return CliRunner().invoke(main, ["filter", str(SMALL), "--jobs", "1", "--limit", "120", *arguments])


def test_a_last_line_cut_short_is_checked_again(tmp_path):
    whole, cut = tmp_path / "whole.jsonl", tmp_path / "cut.jsonl"
    assert _invoke("--verdicts", str(whole)).exit_code == 0
    lines = whole.read_text().splitlines(keepends=True)
    cut.write_text("".join(lines[:41]) + lines[41][:30])  # the header, 40 verdicts, half a line
    result = _invoke("--verdicts", str(cut))
    assert result.exit_code == 0, result.output
    assert "40 verdict(s) read back" in result.output
    assert _lines(cut) == _lines(whole)


def test_a_verdicts_file_of_other_settings_is_refused(tmp_path):
    verdicts = tmp_path / "v.jsonl"
    assert _invoke("--verdicts", str(verdicts), "--seeds", "4").exit_code == 0
    before = verdicts.read_bytes()
    result = _invoke("--verdicts", str(verdicts))
    assert result.exit_code == 1
    assert result.output.splitlines()[-1].startswith(
        f"Error: {verdicts}:1: the verdicts of another scenario, catalogue or step-B settings"
    )
    assert verdicts.read_bytes() == before


def test_a_verdicts_file_of_another_space_is_refused(tmp_path):
    verdicts = tmp_path / "v.jsonl"
    assert _invoke("--verdicts", str(verdicts)).exit_code == 0
    lines = verdicts.read_text().splitlines(keepends=True)
    verdicts.write_text(lines[0] + lines[2] + lines[1])
    result = _invoke("--verdicts", str(verdicts))
    assert result.exit_code == 1
    second = json.loads(lines[2])["composition"]
    first = json.loads(lines[1])["composition"]
    assert result.output.splitlines()[-1] == (
        f"Error: {verdicts}:2: the verdict of {second!r} where the space has {first}: the file is of another space"
    )

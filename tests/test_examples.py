"""examples/ stays true: each script runs on the CPU at a tiny size (a few hundred steps of the
shipped piles), and the friction study runs from the README's own commands."""

import csv
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
#: The tiny size: steps of each run, a frame every so many (a multiple of the examples' gravity_every).
STEPS, EVERY = 300, 30


def readme_study() -> list[list[str]]:
    """The README's friction study: its `decco-warp sweep` of examples/friction_study.toml and the
    `decco-warp compare` that follows, as words."""
    section = (ROOT / "README.md").read_text(encoding="utf-8").split("## A study: does friction change the outcome?", 1)[1].split("\n## ", 1)[0]
    (block,) = re.findall(r"^```bash\n(.*?)^```$", section, flags=re.S | re.M)
    commands = [shlex.split(line.split("#", 1)[0]) for line in block.replace("\\\n", " ").splitlines() if line.startswith("decco-warp ")]
    assert [words[1] for words in commands] == ["sweep", "compare"]
    return commands


def tiny_study(folder: Path) -> Path:
    """examples/friction_study.toml at the tiny size: its grid over mu_k, one eta, two realizations."""
    text = (EXAMPLES / "friction_study.toml").read_text()
    text = re.sub(r"^steps = \d+", f"steps = {STEPS}", text, flags=re.M)
    text = re.sub(r"^output_every = \d+", f"output_every = {EVERY}", text, flags=re.M)
    text = re.sub(r"^realizations = \d+", "realizations = 2", text, flags=re.M)
    text = re.sub(r'^"collision.eta" = .*$', '"collision.eta" = [3.0]', text, flags=re.M)
    text = text.replace("[run]\n", '[run]\ndevice = "cpu"\n')
    path = folder / "friction_study.toml"
    path.write_text(text)
    return path


def decco(*args, cwd):
    return subprocess.run([sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", *args],
                          capture_output=True, text=True, cwd=cwd)  # fmt: skip


@pytest.fixture(scope="module")
def friction(tmp_path_factory):
    """The README's two commands, in a folder of their own, on the tiny copy of the sweep file."""
    here = tmp_path_factory.mktemp("friction")
    sweep, compare = readme_study()
    assert sweep[2] == "examples/friction_study.toml"
    result = decco(*sweep[1:2], str(tiny_study(here)), *sweep[3:], cwd=here)
    assert result.returncode == 0, result.stderr
    compared = decco(*compare[1:], cwd=here)
    return here / "runs" / "out" / "friction", compared


def test_the_friction_study_runs_from_the_readme_s_commands(friction):
    """sweep with a mu_k grid, then compare --by mu_k --at eta: a group per friction coefficient at
    each eta, compared with mu_k 0, from summary.csv's own mu_k column."""
    folder, compared = friction
    assert compared.returncode == 0, compared.stderr
    assert compared.stdout.startswith("largest_mass_ratio by mu_k at eta; reference: 0")
    table = [line.split() for line in compared.stdout.splitlines() if re.match(r"^  (0|0\.3|0\.6) ", line)]
    assert [row[:2] for row in table] == [["0", "2"], ["0.3", "2"], ["0.6", "2"]]
    with (folder / "summary.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert sorted(float(row["mu_k"]) for row in rows) == [0.0, 0.0, 0.3, 0.3, 0.6, 0.6]
    for group, row in zip((0.0, 0.3, 0.6), table):
        values = [float(r["largest_mass_ratio"]) for r in rows if float(r["mu_k"]) == group]
        assert float(row[2]) == pytest.approx(sum(values) / 2, abs=5e-4)  # the mean, as printed to 4 digits
    assert (folder / "figures" / "largest_fragment_intervals.png").is_file()


def test_the_talk_figure_draws_the_study(friction, tmp_path):
    folder, _ = friction
    result = subprocess.run([sys.executable, str(EXAMPLES / "talk_figure.py"), str(folder), "--out", str(tmp_path / "talk")],
                            capture_output=True, text=True)  # fmt: skip
    assert result.returncode == 0, result.stderr
    for suffix in (".png", ".pdf"):
        assert (tmp_path / f"talk{suffix}").stat().st_size > 5000


def test_reading_the_data_without_pandas(friction):
    folder, _ = friction
    result = subprocess.run([sys.executable, str(EXAMPLES / "read_data.py"), str(folder)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert f"{folder / 'summary.csv'}: 6 runs" in result.stdout and "largest_mass_ratio by mu_k at eta" in result.stdout
    assert "analysed frames; m_lf/m_t from" in result.stdout and "catalogue:" in result.stdout and "trajectory.h5: 11 frames of 450 particles" in result.stdout


def test_the_spin_study_runs_and_compares_its_kinds(tmp_path):
    result = subprocess.run([sys.executable, str(EXAMPLES / "spin_study.py"), "--steps", str(STEPS), "--realizations", "2",
                             "--out", str(tmp_path), "--device", "cpu"], capture_output=True, text=True)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "largest_mass_ratio by spin_kind at eta; reference: anti-parallel" in result.stdout
    with (tmp_path / "spin" / "summary.csv").open(newline="") as f:
        kinds = sorted(row["spin_kind"] for row in csv.DictReader(f))
    assert kinds == ["anti-parallel", "anti-parallel", "parallel", "parallel"]


def test_every_example_is_run_by_a_test():
    tested = Path(__file__).read_text()
    for script in EXAMPLES.glob("*.py"):
        assert script.name in tested, f"{script.name} has no test"

"""The recording format and the offline estimator (estimator.recording, estimator.estimate)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from coop_gym.experiment import protocol
from estimator import estimate
from estimator.identification.identify import Trial, identify
from estimator.recording import Recording, RecordingError, format_recording, parse_recording, read_recording

HEADER = "time_s,shoulder_position_m,force_n,verbal_cue,requested_xi\n"


def _rows(n: int = 60) -> str:
    return "".join(f"{0.02 * k!r},0.0,0.0,{int(k >= 10)},1\n" for k in range(n))


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("export")
    args = ["--subjects", "2", "--trials", "12", "--seed", "3", "--export", str(folder), "--json"]
    assert protocol.main(args) == 0
    return folder


def test_estimate_gives_the_protocols_balanced_accuracy(exported: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("kalman", "imm"):
        out = protocol.run_protocol(protocol.ProtocolConfig(n_subjects=2, n_trials=12), seed=3, estimator=name)
        capsys.readouterr()
        assert estimate.main([str(exported), "--estimator", name, "--json"]) == 0
        offline = json.loads(capsys.readouterr().out)
        assert offline["n_labelled"] == 24
        assert offline["confusion"] == out["confusion"]
        assert offline["balanced_accuracy"] == out["balanced_accuracy"]
        assert offline["log_loss"] == pytest.approx(out["log_loss"], rel=1e-9)


def test_a_written_recording_reads_back_exactly() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(50, dtype=np.float64) * 0.02
    rec = Recording(t, rng.normal(size=50), rng.normal(size=50), np.r_[np.zeros(5), np.ones(45)],
                    requested_xi=np.full(50, -1.0), meta={"subject": "a"})  # fmt: skip
    back = parse_recording(format_recording(rec))
    np.testing.assert_array_equal(back.shoulder_position_m, rec.shoulder_position_m)
    np.testing.assert_array_equal(back.force_n, rec.force_n)
    assert back.requested == -1 and back.meta["subject"] == "a" and back.cue_force_n is None


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("time_s,shoulder_position_m,force_n\n0,0,0\n", "line 1: missing column(s) verbal_cue"),
        ("time_s,shoulder_position_m,force_n,verbal_cue,colour\n", "line 1, column 5: unknown column 'colour'"),
        (HEADER + "0.0,0.0,0.0,0,1\n0.02,abc,0.0,0,1\n", "line 3, column 2 (shoulder_position_m): not a number"),
        (HEADER + "0.0,0.0,0.0,2,1\n0.02,0,0,0,1\n", "line 2, column 4 (verbal_cue): must be -1, 0 or 1"),
        (HEADER + "0.0,0,0,0,1\n0.02,0,0,0,1\n0.05,0,0,0,1\n", "line 4, column 1 (time_s): samples must be evenly"),
        (HEADER + "0.0,0,0,0,1\n0.02,0,0,0,0\n", "line 3, column 5 (requested_xi): must be the same"),
        (HEADER + "0.0,0,0,0,1\n0.02,0,nan,0,1\n", "line 3, column 3 (force_n): not finite"),
        (HEADER + "0.0,0,0,0,1\n0.02,0,0\n", "line 3: 3 fields, the header has 5"),
        ('# model: {"dt_s": 0.02, "lambda": 1}\n' + HEADER + _rows(), "line 1: bad model"),
    ],
)
def test_a_bad_file_is_refused_naming_line_and_column(text: str, where: str) -> None:
    with pytest.raises(RecordingError, match="bad.csv, " + where.replace("(", r"\(").replace(")", r"\)")):
        parse_recording(text, name="bad.csv")


def test_the_command_line_names_the_bad_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "r.csv"
    path.write_text(HEADER + "0.0,0,0,0,1\n0.02,x,0,0,1\n")
    assert estimate.main([str(path)]) == 1
    assert f"{path}, line 3, column 2" in capsys.readouterr().err


def test_identify_fits_recordings_through_the_reader(exported: Path) -> None:
    recordings = [read_recording(p) for p in sorted(exported.glob("*_s00_*.csv"))]
    trials = [Trial.from_recording(r) for r in recordings]
    assert [t.xi for t in trials] == [r.requested for r in recordings]
    fit = identify(trials[:4], initial=recordings[0].model, restarts=1, max_iterations=20)
    assert np.isfinite(fit.negative_log_likelihood)


def test_the_plot_and_an_empty_folder(exported: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    first = sorted(exported.glob("*.csv"))[0]
    assert estimate.main([str(first), "--plot", str(tmp_path / "trace.png")]) == 0
    assert (tmp_path / "trace.png").stat().st_size > 0
    (tmp_path / "empty").mkdir()
    assert estimate.main([str(tmp_path / "empty")]) == 1
    assert "no recordings" in capsys.readouterr().err


def test_no_recording_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert estimate.main([]) == 2
    assert "error: give at least one recording" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("plot", "message"),
    [("trace.txt", "--plot: unsupported file type '.txt'"), ("missing/trace.png", "is not a writable folder")],
)
def test_a_plot_that_cannot_be_written_is_refused_before_any_work(
    exported: Path, tmp_path: Path, plot: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert estimate.main([str(exported), "--plot", str(tmp_path / plot)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and not list(tmp_path.glob("**/trace*"))

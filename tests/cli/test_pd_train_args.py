"""pd-train refuses out-of-range flags with one line, before it builds or writes anything."""

from __future__ import annotations

import pytest
import torch

from pd_core.cli import train as pd_train


@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--episodes", "-3"], "episodes must be > 0"),
        (["--num-envs", "0"], "num_envs must be > 0"),
        (["--updates-per-step", "0"], "updates_per_step must be > 0"),
        (["--epsilon0", "1.5"], "epsilon0"),
        (["--max-minutes", "-1"], "max_minutes must be >= 0"),
        pytest.param(
            ["--device", "cuda"],
            "sees no CUDA device",
            marks=pytest.mark.skipif(torch.cuda.is_available(), reason="a CUDA device is here"),
        ),
    ],
)
def test_bad_flag_is_one_line_and_writes_no_run(tmp_path, capsys, flags, named):
    run = tmp_path / "run"
    assert pd_train.main([*flags, "--run-dir", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0], err
    assert not run.exists()


def test_resume_from_nowhere_is_one_line(tmp_path, capsys):
    assert pd_train.main(["--resume", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no checkpoint" in err[0], err


def test_help_documents_the_device_and_the_papers_update_ratio(capsys):
    with pytest.raises(SystemExit) as exc:
        pd_train.main(["--help"])
    assert exc.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "--device {auto,cpu,cuda}" in out and "CUDA graph" in out
    assert "--num-envs N give --updates-per-step N" in out


def test_an_unknown_device_is_refused_by_the_parser(capsys):
    with pytest.raises(SystemExit) as exc:
        pd_train.main(["--device", "tpu"])
    assert exc.value.code == 2
    assert "invalid choice: 'tpu'" in capsys.readouterr().err

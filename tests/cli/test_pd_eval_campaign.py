"""pd-eval --dispersions: one table of every scenario x every agent, its JSON and PNG."""

from __future__ import annotations

import json

from pd_core.cli import evaluate as pd_eval


def test_campaign_table_json_and_png(tmp_path, capsys):
    out = tmp_path / "camp"
    argv = ["--controller", "zemzev", "--name", "zz", "--episodes", "40", "--seed", "3"]
    argv += ["--dispersions", "nominal,delay,all", "--compare", "again=controller:zemzev"]
    assert pd_eval.main(argv + ["--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    for word in ("scenario", "success %", "miss p99 m", "worst vk m/s", "fuel p50 kg", "delay"):
        assert word in text
    t = json.loads((out / "campaign.json").read_text())
    assert [d["name"] for d in t["scenarios"]] == ["nominal", "delay", "all"]
    assert t["agents"] == ["zz", "again"]
    for name in ("nominal", "delay", "all"):
        a, b = t["results"][name]["zz"], t["results"][name]["again"]
        assert a == b  # the same controller on the same seeds: the same numbers
        assert a["episodes"] == 40 and 0.0 <= a["success_rate"] <= 1.0
        assert a["miss_median_m"] <= a["miss_p99_m"]
        assert a["layer_changed_rate"] is None  # a bare controller has no runtime layer
    assert t["results"]["nominal"]["zz"]["success_rate"] == 1.0
    assert t["results"]["all"]["zz"]["success_rate"] < 1.0  # the combined case bites
    assert (out / "campaign.png").stat().st_size > 5000


def test_failed_episodes_are_listed_and_fly_again_from_their_seed(tmp_path, capsys):
    argv = ["--controller", "zemzev", "--name", "zz", "--episodes", "40", "--seed", "3"]
    assert pd_eval.main(argv + ["--dispersions", "all", "--out", str(tmp_path / "c")]) == 0
    text = capsys.readouterr().out
    cell = json.loads((tmp_path / "c" / "campaign.json").read_text())["results"]["all"]["zz"]
    failed = cell["failed_episodes"]
    assert failed["count"] == round(40 * (1 - cell["success_rate"])) > 0
    assert len(failed["listed"]) == failed["count"]  # under the listing limit
    assert failed["episodes"] == [e["episode"] for e in failed["listed"]]  # every index
    assert f"all / zz: {failed['count']} failed: seed {failed['listed'][0]['seed']}" in text
    for e in failed["listed"]:
        assert e["seed"] == 3 + e["episode"]
        assert e["outcome"] and (
            e["miss_m"] >= 5.0 or e["speed_mps"] >= 2.0 or "time" in e["outcome"]
        )
    e = failed["listed"][0]
    again = ["--controller", "zemzev", "--name", "zz", "--episodes", "1", "--seed", str(e["seed"])]
    assert pd_eval.main(again + ["--dispersions", "all", "--out", str(tmp_path / "one")]) == 0
    capsys.readouterr()
    one = json.loads((tmp_path / "one" / "campaign.json").read_text())["results"]["all"]["zz"]
    assert one["failed_episodes"]["listed"] == [{**e, "episode": 0}]


def test_campaign_from_yaml_and_refusals(tmp_path, capsys):
    f = tmp_path / "mine.yaml"
    f.write_text("scenarios:\n  - {name: heavy, mass_kg: [2150, 2250]}\n")
    argv = ["--controller", "zemzev", "--episodes", "20", "--dispersions", str(f), "--json"]
    assert pd_eval.main(argv + ["--out", str(tmp_path / "o"), "--no-progress"]) == 0
    t = json.loads(capsys.readouterr().out)
    assert list(t["results"]) == ["heavy"]
    assert t["scenarios"][0]["mass_kg"] == [2150.0, 2250.0]
    assert pd_eval.main(["--controller", "zemzev", "--dispersions", "windy"]) == 2
    assert "unknown dispersion scenario" in capsys.readouterr().err


def test_long_scenario_and_agent_names_keep_their_columns(tmp_path, capsys):
    f = tmp_path / "long.yaml"
    f.write_text("scenarios:\n  - {name: delay2-thrust-misalignment, delay_steps: 2}\n")
    argv = ["--controller", "zemzev", "--name", "zz", "--episodes", "4", "--dispersions", str(f)]
    argv += ["--compare", "zemzev-behind-its-own-layer=layer:controller:zemzev"]
    assert pd_eval.main(argv + ["--out", str(tmp_path / "o"), "--no-progress"]) == 0
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("delay2-")]
    assert len(rows) == 2
    for r in rows:  # name, agent and seven figures, each separated by spaces
        assert len(r.split()) == 9, r
    # the layer's share: '-' for the bare controller, a percentage behind the layer
    assert rows[0].split()[-1] == "-" and 0.0 <= float(rows[1].split()[-1]) <= 100.0

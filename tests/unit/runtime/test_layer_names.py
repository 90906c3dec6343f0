"""One word for what flies around the network: "layer" (issue 70 item 6). The old names ("shield")
still work for one release and warn, naming the new one: `load_policy(shield=)`,
`SHIELD_MODES`, the `shield:` spec prefix, a training config's "shield" (old run folders, policy
files' metadata), `TrainConfig.shield`, `pd-train --shield` and pd-sweep's `shield=`. Each flies
exactly what its new name flies."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import pd_core
from pd_core.cli import evaluate as pd_eval
from pd_core.cli import train as pd_train
from pd_core.deprecation import RenamedWarning
from pd_core.dqn.config import TrainConfig, current_names, from_args, preset
from pd_core.episodes import rollout
from pd_core.runtime import policy_file
from pd_core.runtime.build import build
from pd_core.runtime.config import RuntimeConfig

MODELS = Path(__file__).resolve().parents[3] / "models"
ROBUST = MODELS / "pd_dqn_robust.pt"


def test_load_policy_takes_layer_and_its_old_name_shield_warns():
    for load in (pd_core.load_policy, policy_file.load_policy):
        for mode in policy_file.LAYER_MODES:
            want = load(ROBUST, layer=mode).config
            with pytest.warns(DeprecationWarning, match=r"load_policy\(layer=\.\.\.\)"):
                assert load(ROBUST, shield=mode).config == want
        with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="disagree"):
            load(ROBUST, layer="never", shield="always")
    assert policy_file.load_policy(ROBUST, "never").config.is_off  # positional, as before


def test_the_new_names_do_not_warn(recwarn):
    pd_core.load_policy(ROBUST, layer="always")
    build("layer:controller:zemzev")
    assert preset("ocp").layer and preset("ocp", layer=False).layer is False
    from_args(pd_train.build_parser().parse_args(["--layer"]))
    assert not [w for w in recwarn if issubclass(w.category, RenamedWarning)]


def test_shield_modes_is_the_old_name_of_layer_modes():
    with pytest.warns(DeprecationWarning, match="use pd_core.runtime.policy_file.LAYER_MODES"):
        assert policy_file.SHIELD_MODES == policy_file.LAYER_MODES == ("file", "always", "never")
    with pytest.raises(AttributeError):
        _ = policy_file.NO_SUCH_NAME


def test_the_shield_spec_prefix_flies_what_layer_flies():
    for new in (
        "layer:controller:zemzev",
        f"layer:{ROBUST}",
        "set:nav_filter=0:layer:controller:zemzev",
    ):
        old = new.replace("layer:", "shield:")
        with pytest.warns(DeprecationWarning, match="'shield:' is deprecated, use 'layer:'"):
            was = build(old)
        now = build(new)
        assert was.label == now.label and was.runtime.config == now.runtime.config
    assert now.label == "controller zemzev + layer (nav_filter=0)"
    assert build(f"layer:{ROBUST}").runtime.config == RuntimeConfig()
    with pytest.warns(DeprecationWarning):
        old = rollout(build("shield:controller:zemzev").actor, 3, 5, dispersions="delay")
    new = rollout(build("layer:controller:zemzev").actor, 3, 5, dispersions="delay")
    np.testing.assert_array_equal(old.final_states, new.final_states)


def test_pd_eval_says_so_in_one_line_for_an_old_spec(capsys):
    argv = ["--controller", "zemzev", "--episodes", "2", "--compare", "zz=shield:controller:zemzev"]
    assert pd_eval.main(argv) == 0
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        "pd-eval: the spec prefix 'shield:' is deprecated, use 'layer:' (the old name goes in the "
        "next release)"
    ]


def test_a_training_config_with_shield_reads_as_layer():
    new = preset("ocp").to_dict()
    assert new["layer"] is True and "shield" not in new
    old = {k if k != "layer" else "shield": v for k, v in new.items()}
    with pytest.warns(DeprecationWarning, match="field 'shield' is deprecated, use 'layer'"):
        assert TrainConfig.from_dict(old) == preset("ocp")
    with pytest.warns(DeprecationWarning):  # an old config resumed with the new flag given
        assert TrainConfig.from_dict(old, {"layer": False}).layer is False
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="disagree"):
        current_names({"shield": True, "layer": False})
    with pytest.warns(DeprecationWarning):
        assert preset("ocp-adapt", shield=False).layer is False


@pytest.mark.parametrize("model", sorted(p.stem for p in MODELS.glob("*.pt")))
def test_every_shipped_files_training_config_still_reads(model):
    """A file's metadata keeps its training config as it was written, "shield" and all; it reads
    with `layer` (what the file flies is its pinned runtime config, which the rename left
    alone). A file trained after the rename has `layer` itself."""
    config = json.loads((MODELS / f"{model}.json").read_text())["training"]["config"]
    if "layer" in config:  # trained after the rename
        assert "shield" not in config
        assert TrainConfig.from_dict(config).layer is config["layer"]
        return
    if "shield" not in config:  # trained before there was one
        assert TrainConfig.from_dict(config).layer is False
        return
    with pytest.warns(DeprecationWarning, match="field 'shield'"):
        assert TrainConfig.from_dict(config).layer is config["shield"]


def test_the_old_attribute_warns_and_is_the_new_one():
    cfg = preset("best")
    with pytest.warns(DeprecationWarning, match=r"TrainConfig\.shield is deprecated"):
        assert cfg.shield is False
    with pytest.warns(DeprecationWarning):
        cfg.shield = True
    assert cfg.layer is True


def test_pd_train_takes_shield_as_the_old_flag_of_layer(capsys):
    parser = pd_train.build_parser()
    with pytest.warns(DeprecationWarning, match="--shield is deprecated, use --layer"):
        assert from_args(parser.parse_args(["--preset", "best", "--shield"])).layer is True
    with pytest.warns(DeprecationWarning):
        assert from_args(parser.parse_args(["--shield", "0", "--layer", "0"])).layer is False
    assert "deprecated: the old name of --layer" in parser.format_help()
    assert pd_train.main(["--preset", "best", "--shield", "--print-config"]) == 0
    out = capsys.readouterr()
    assert json.loads(out.out)["layer"] is True
    assert out.err.splitlines() == [
        "pd-train: --shield is deprecated, use --layer (the old name goes in the next release)"
    ]
    assert pd_train.main(["--shield", "1", "--layer", "0", "--print-config"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "pd-train: --shield and --layer disagree (give only --layer)"

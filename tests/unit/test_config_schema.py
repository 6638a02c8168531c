"""The config schema: every shipped config passes it, and every group refuses a wrong type, an
out-of-range value and an unknown key before any work, naming the key, the value and what is
allowed (``kinet_rl.config_schema``, ``kinet_rl.pipeline.check_config``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import ConfigCompositionException
from omegaconf import OmegaConf

from kinet_rl import evaluate, plan, train
from kinet_rl import tables as tables_module
from kinet_rl.config_schema import ConfigError, check_arguments, conform, describe
from kinet_rl.configs import config_dir
from kinet_rl.envs import SceneSettings, make_dm_env
from kinet_rl.pipeline import ExperimentSettings, check_config
from kinet_rl.tables import TablesSettings, build_tables, check_rows

CONF = Path(config_dir())
EXPERIMENTS = sorted(p.stem for p in (CONF / "exp").glob("*.yaml"))
SCALES = sorted(p.stem for p in (CONF / "scale").glob("*.yaml"))
TABLE_SCALES = sorted(p.stem for p in (CONF / "tables").glob("*.yaml"))
#: Experiments whose study fixes its scale (their defaults list one; `+scale` is refused).
SCALED = [
    name for name in EXPERIMENTS if "- /scale:" in (CONF / "exp" / f"{name}.yaml").read_text()
]
#: Experiments and comparison-table scales whose check needs the YCB meshes (marked ``ycb``, so
#: skipped without ``$KINET_RL_YCB_DIR``): VisIN on YCBObjs builds the YCB scene for the camera
#: projection of its crops. Every other model checks its YCB experiment without the assets.
YCB_EXPERIMENTS = [
    name for name in EXPERIMENTS if name.startswith("ycb_") and name.endswith("_visin")
]


def tables_task(scale: str) -> str | None:
    """The ``task`` of a ``tables`` config: its own, or the first one its defaults list gives."""
    config = OmegaConf.load(CONF / "tables" / f"{scale}.yaml")
    if "task" in config:
        return config.task
    parents = [d for d in config.get("defaults", []) if isinstance(d, str) and d != "_self_"]
    return next((task for d in parents if (task := tables_task(d)) is not None), None)


YCB_TABLE_SCALES = [scale for scale in TABLE_SCALES if tables_task(scale) == "ycb"]


def experiment_case(*overrides: str) -> Any:
    """A ``pytest.param`` of ``overrides``, marked ``ycb`` for an experiment of YCB_EXPERIMENTS."""
    ycb = bool(overrides) and overrides[0].removeprefix("+exp=") in YCB_EXPERIMENTS
    return pytest.param(
        list(overrides), marks=[pytest.mark.ycb] if ycb else [], id=",".join(overrides) or "default"
    )


def compose_config(*overrides: str, config_name: str = "config"):
    with initialize_config_dir(str(CONF), version_base="1.3"):
        return compose(config_name=config_name, overrides=list(overrides))


def container(*overrides: str) -> dict[str, Any]:
    return OmegaConf.to_container(compose_config(*overrides), resolve=True)


def tables_settings(*overrides: str) -> TablesSettings:
    cfg = compose_config(*overrides, config_name="tables")
    return TablesSettings.from_container(OmegaConf.to_container(cfg.tables, resolve=True))


@pytest.mark.parametrize(
    "overrides",
    [experiment_case()]
    + [experiment_case(f"+exp={name}") for name in EXPERIMENTS]
    + [
        experiment_case(f"+exp={name}", f"+scale={scale}")
        for name in EXPERIMENTS
        if name not in SCALED
        for scale in SCALES
    ],
)
def test_every_shipped_experiment_and_scale_passes(overrides: list[str]) -> None:
    settings = check_config(container(*overrides))
    assert isinstance(settings.scene, SceneSettings)
    assert settings.name == (overrides[0].removeprefix("+exp=") if overrides else "default")


def test_the_unseen_objects_study_holds_out_objects_by_name_at_the_cpu_scale() -> None:
    assert SCALED == ["ycb_topview_unseen"]
    config = container("+exp=ycb_topview_unseen")
    ((name, held_out),) = config["data"]["generalization"].items()
    seen, unseen = set(config["env"]["ycb_objects"]), set(held_out["env"]["ycb_objects"])
    assert len(seen) == 9 and len(unseen) == 3 and not seen & unseen
    assert (
        config["trainer"]["steps"]
        == container("+exp=ycb_topview", "+scale=cpu")["trainer"]["steps"]
    )
    top_cpu = container("+exp=ycb_topview", "+scale=cpu", "env.image_size=64")["data"]["name"]
    assert len({config["data"]["name"], name, top_cpu}) == 3  # its own datasets
    with pytest.raises(ConfigCompositionException, match="scale appears more than once"):
        container("+exp=ycb_topview_unseen", "+scale=cpu")


def test_ycb_experiments_default_to_the_measured_image_size() -> None:
    """96 px on YCBObjs (chosen over 64 and 128 px, docs/results.md), 64 px on BlockObjs; the
    unseen-objects study keeps the 64 px it ran at, which its dataset names say."""
    assert container("+exp=ycb_sideview")["env"]["image_size"] == 96
    assert container("+exp=ycb_topview_vcdn", "+scale=cpu")["data"]["name"] == "ycb_top96_cpu"
    assert container("+exp=blocks_topview")["env"]["image_size"] == 64
    unseen = container("+exp=ycb_topview_unseen")
    assert unseen["env"]["image_size"] == 64 and "top64" in unseen["data"]["name"]


def test_keypoint_models_take_k_from_the_experiment_and_the_others_have_none() -> None:
    """K = 6 on BlockObjs, 9 on YCBObjs (paper), for KINet and V-CDN; IN, IN-full, VisIN, Forw,
    ForwInv of the YCB tables compose without a keypoint count they would refuse."""
    for exp, k in (("blocks_topview", 6), ("ycb_sideview", 9), ("ycb_topview_vcdn", 9)):
        assert container(f"+exp={exp}")["model"]["num_keypoints"] == k
    assert container("+exp=ycb_sideview", "keypoints=12")["model"]["num_keypoints"] == 12
    for baseline in ("in", "in_full", "visin", "forw", "forwinv"):
        model = container(f"+exp=ycb_sideview_{baseline}")["model"]
        assert "num_keypoints" not in model and model["_target_"].startswith("kinet_rl.baselines")
    ycb = tables_settings("tables=cpu_ycb")
    assert (ycb.task, ycb.mpc_camera) == ("ycb", "side")


def test_kinet_plans_with_the_cost_chosen_on_validation_for_its_task() -> None:
    """Unsquared keypoint distances on YCBObjs, squared on BlockObjs (docs/results.md); V-CDN
    plans with its own model whichever the task."""
    expected = {
        "ycb_sideview": "kinet_keypoints_distance",
        "ycb_topview": "kinet_keypoints_distance",
        "ycb_topview_unseen": "kinet_keypoints_distance",
        "ycb_sideview_determ": "kinet_keypoints_distance",
        "blocks_topview": "kinet_keypoints_l2",
        "ycb_topview_vcdn": "model_mpc",
    }
    for exp, method in expected.items():
        eval_cfg = container(f"+exp={exp}")["eval"]
        assert eval_cfg["kinet_method"] == method, exp
        assert method in eval_cfg["methods"], exp


@pytest.mark.parametrize(
    "scale",
    [
        pytest.param(s, marks=[pytest.mark.ycb] if s in YCB_TABLE_SCALES else [])
        for s in TABLE_SCALES
    ],
)
def test_every_tables_scale_and_its_rows_pass(scale: str) -> None:
    tables = tables_settings(f"tables={scale}")
    assert tables.scale == scale
    with initialize_config_dir(str(CONF), version_base="1.3"):
        check_rows(tables)  # composes and checks each row's training and MPC settings


def test_evaluate_and_plan_check_their_shipped_defaults() -> None:
    settings = evaluate.settings_from_config(compose_config())
    assert settings.methods and settings.planner["top_k"] <= settings.planner["num_candidates"]
    args = plan.parse_args(["--checkpoint", "k.pt", "--image", "a.png", "--goal", "b.png"])
    assert plan.planner_overrides(args) == {}  # the checkpoint's planner settings
    assert args.objective is None and not args.resize


#: (overrides, the key the error names, a fragment of the error: the value or what is allowed).
REFUSED = {
    # root keys
    "root type": (["seed=zero"], "seed", "got 'zero', expected an integer"),
    "root range": (["device=gpu"], "device", "expected auto or a torch device"),
    "root unknown": (["+epochs=3"], "epochs", "unknown key (set to 3)"),
    # env
    "env type": (["env.num_objects=three"], "env.num_objects", "got 'three', expected an integer"),
    "env objects": (["env.num_objects=6"], "env.num_objects", "got 6, expected an integer from 1"),
    "env size": (["env.image_size=30"], "env.image_size", "got 30, expected a multiple of 4"),
    "env small": (["env.image_size=8"], "env.image_size", "of at least 16 pixels"),
    "env unknown": (["+env.colour=red"], "env.colour", "allowed keys: background, camera"),
    # data, its policy and its generalization sets
    "data type": (["data.num_workers=two"], "data.num_workers", "got 'two', expected an integer"),
    "data range": (["data.chunk_episodes=0"], "data.chunk_episodes", "of at least 1"),
    "data unknown": (["+data.episodes=5"], "data.episodes", "did you mean num_episodes?"),
    "data splits": (["data.num_episodes=5"], "data.splits", "empty: ['val']"),
    "policy range": (["data.policy.keep_inside=2"], "data.policy.keep_inside", "in (0, 1]"),
    "policy unknown": (["+data.policy.noise=1"], "data.policy.noise", "unknown key"),
    "object counts low": (
        ["data.num_objects_range=[0,3]"],
        "data.num_objects_range",
        "got [0, 3], expected null (one count, env.num_objects) or [low, high] with 1 <= low",
    ),
    "object counts high": (["data.num_objects_range=[2,6]"], "data.num_objects_range", "<= 5"),
    "object counts order": (["data.num_objects_range=[4,2]"], "data.num_objects_range", "[4, 2]"),
    "object counts type": (["data.num_objects_range=3"], "data.num_objects_range", "got 3"),
    "object counts model": (
        ["model=in", "loss=in", "data.num_objects_range=[1,5]"],
        "data.num_objects_range",
        "ObjectInteractionModel learns from every object's ground-truth position",
    ),
    "generalization": (
        ["+data.generalization.many.num_episodes=2", "+data.generalization.many.env.num_objects=9"],
        "data.generalization.many.env.num_objects",
        "got 9, expected an integer from 1 to 5",
    ),
    # model: each model's keys are its constructor's
    "kinet type": (["model.num_keypoints=six"], "model.num_keypoints", "expected an integer"),
    "kinet range": (["model.num_keypoints=0"], "model", "must be positive, got 0"),
    "kinet choice": (["model.feature_grad=haed"], "model", "feature_grad='haed'; choose one"),
    "kinet unknown": (
        ["+model.num_keypoint=6"],
        "model.num_keypoint",
        "did you mean num_keypoints",
    ),
    "forw type": (["model=forw", "loss=forw", "model.num_down=3.5"], "model.num_down", "got 3.5"),
    "forw unknown": (
        ["model=forw", "loss=forw", "+model.num_keypoints=6"],
        "model.num_keypoints",
        "allowed keys: channels, feature_dim",
    ),
    "forwinv unknown": (
        ["model=forwinv", "loss=forwinv", "+model.blob_std=0.1"],
        "model.blob_std",
        "unknown key",
    ),
    "in unknown": (["model=in", "loss=in", "+model.feat_dim=16"], "model.feat_dim", "unknown key"),
    "visin range": (
        ["model=visin", "loss=visin", "model.crop_resolution=2"],
        "model",
        "crop_resolution >= 4",
    ),
    # loss
    "loss type": (["loss.ctr_weight=heavy"], "loss.ctr_weight", "got 'heavy', expected a number"),
    "loss range": (["loss.ctr_temperature=0"], "loss", "ctr_temperature must be > 0"),
    "loss unknown": (["+loss.ctr_wieght=1"], "loss.ctr_wieght", "did you mean ctr_weight?"),
    "loss of another model": (["model=forw"], "loss", "KINetLoss trains a KINetWorldModel"),
    # trainer (conf/config.yaml)
    "trainer type": (["trainer.steps=abc"], "trainer.steps", "got 'abc', expected an integer"),
    "trainer range": (["trainer.steps=-1"], "trainer.steps", "got -1, expected an integer of at"),
    "trainer unknown": (["+trainer.stepz=3"], "trainer.stepz", "did you mean steps?"),
    "trainer episode": (["env.max_steps=2"], "trainer.horizon", "at most env.max_steps=2"),
    "trainer precision": (
        ["trainer.precision=float16"],
        "trainer.precision",
        "got 'float16', expected one of ('float32', 'bfloat16')",
    ),
    "trainer compile": (["trainer.compile=maybe"], "trainer.compile", "expected true or false"),
    "trainer batch": (
        ["trainer.batch_size=30", "trainer.steps_per_episode=4"],
        "trainer.steps_per_episode",
        "a divisor of batch_size=30",
    ),
    # report
    "report type": (["report.num_sequences=many"], "report.num_sequences", "got 'many'"),
    "report range": (["report.horizons=[0]"], "report.horizons", "integers of at least 1"),
    "report unknown": (["+report.horizon=1"], "report.horizon", "did you mean horizons?"),
    # eval and its planners
    "eval type": (["eval.episodes=one"], "eval.episodes", "got 'one', expected an integer"),
    "eval range": (["eval.num_objects=[1,9]"], "eval.num_objects", "integers from 1 to 5"),
    "eval unknown": (["+eval.epsiodes=3"], "eval.epsiodes", "did you mean episodes?"),
    "eval split": (["eval.split=train"], "eval.split", "got 'train', expected one of 'validation'"),
    # the oracle plans with eval.planner and the split sets the seeds: these keys are gone
    "eval old oracle": (["+eval.oracle_planner.top_k=8"], "eval.oracle_planner", "unknown key"),
    "eval old seed": (["+eval.seed=3"], "eval.seed", "allowed keys: "),
    "eval method": (["eval.methods=[kinet_grpah]"], "eval", "Unknown methods ['kinet_grpah']"),
    "planner range": (
        ["eval.planner.top_k=100"],
        "eval.planner.top_k",
        "at most num_candidates=64",
    ),
    "planner type": (["eval.planner.optim_steps=x"], "eval.planner.optim_steps", "got 'x'"),
    "planner unknown": (["+eval.planner.topk=1"], "eval.planner.topk", "did you mean top_k?"),
    # logger
    "logger type": (["logger.wandb_kwargs=3"], "logger.wandb_kwargs", "expected a mapping"),
    "logger range": (["logger.kind=tb"], "logger.kind", "got 'tb', expected one of ('csv'"),
    "logger unknown": (["+logger.project=x"], "logger.project", "allowed keys: kind, wandb_kwargs"),
    # an experiment and a scale are deltas of the groups above
    "exp": (["+exp=smoke", "report.horizons=[1,6]"], "report.horizons", "at most env.max_steps=5"),
    "scale": (["+exp=smoke", "+scale=cpu", "data.num_episodes=-3"], "data.num_episodes", "got -3"),
}


@pytest.mark.parametrize(("overrides", "key", "fragment"), REFUSED.values(), ids=list(REFUSED))
def test_each_group_refuses_bad_values_naming_them(overrides, key, fragment) -> None:
    with pytest.raises(ConfigError) as info:
        check_config(container(*overrides))
    assert info.value.key == key
    assert fragment in str(info.value) and str(info.value).startswith(f"Config entry {key}: ")


@pytest.mark.parametrize(
    ("overrides", "key", "fragment"),
    [
        (["tables.seeds=[a]"], "tables.seeds", "got ['a'], expected a list of integers"),
        (["tables.mpc_camera=front"], "tables.mpc_camera", "expected one of cameras"),
        (["tables.models=[kinet,forwards]"], "tables.models", "names from ['kinet'"),
        (["+tables.model=[kinet]"], "tables.model", "did you mean models?"),
        (  # no budget is no MPC (Table I alone): nothing to run Table II at
            ["~tables.mpc_budgets", "+tables.mpc_budgets={}"],
            "tables.generalization_models",
            "models that plan at the first of mpc_budgets",
        ),
        (  # a budget set to null is dropped
            ["tables.mpc_budgets={64x3: null}"],
            "tables.generalization_models",
            "there is none",
        ),
        (
            ["++tables.mpc_budgets={64x3: {episodes: 0}}"],
            "tables.mpc_budgets.64x3.episodes",
            "got 0",
        ),
        (
            ["++tables.mpc_budgets={64x3: {models: [in]}}"],
            "tables.generalization_models",
            "models that plan at the first",
        ),
        (
            ["++tables.mpc_budgets={64x3: {models: [ycb]}}"],
            "tables.mpc_budgets.64x3.models",
            "a non-empty list of names from models",
        ),
        (["+tables.mpc_budgets={cheap: 3}"], "tables.mpc_budgets.cheap", "expected a mapping"),
        (["+tables.mpc_seeds=[7]"], "tables.mpc_seeds", "a non-empty list of seeds from [0]"),
        (["+tables.camera_overrides={front: []}"], "tables.camera_overrides", "from ['top'"),
        (
            ["+tables.variants={k3: {model: kinet}}"],
            "tables.variants.k3.label",
            "missing; this key is required",
        ),
        (
            ["+tables.variants={k3: {model: kinet_k, label: K}}"],
            "tables.variants.k3.model",
            "got 'kinet_k', expected one of ['kinet'",
        ),
        (  # its run would be KINet-determ's
            ["+tables.variants={determ: {model: kinet, label: D}}"],
            "tables.variants",
            "gives its run a folder of its own",
        ),
        (
            ["+tables.variants={k3: {model: kinet, label: K, override: ['keypoints=3']}}"],
            "tables.variants.k3.override",
            "did you mean overrides?",
        ),
        (["tables.models=[kinet,k3]"], "tables.models", "names from ['kinet'"),
        (["+tables.mpc_budgets={a/b: {top_k: 2}}"], "tables.mpc_budgets", "they name files"),
        (
            ["+tables.mpc_budgets={cheap: {topk: 2}}"],
            "tables.mpc_budgets.cheap.topk",
            "did you mean top_k?",
        ),
        (["+tables.mpc_budgets={cheap: {top_k: x}}"], "tables.mpc_budgets.cheap.top_k", "got 'x'"),
        (["~tables.mpc_budgets"], "tables.mpc_budgets", "missing; this key is required"),
    ],
)
def test_the_tables_group_refuses_bad_values_naming_them(overrides, key, fragment) -> None:
    with pytest.raises(ConfigError) as info:
        tables_settings(*overrides)
    assert info.value.key == key and fragment in str(info.value)


def test_a_bad_row_override_is_refused_before_any_row_trains(tmp_path: Path, monkeypatch) -> None:
    def run_row(*args):
        raise AssertionError("a row ran before every row's config was checked")

    monkeypatch.setattr(tables_module, "run_row", run_row)
    tables = tables_settings("tables=laptop")
    bad = dataclasses.replace(tables, overrides=(*tables.overrides, "trainer.log_every=abc"))
    with initialize_config_dir(str(CONF), version_base="1.3"):
        with pytest.raises(ConfigError, match="trainer.log_every: got 'abc'.*row blocks_topview"):
            build_tables(bad, tmp_path)
        with pytest.raises(ConfigError, match="tables.eval.episodes: got 0"):
            check_rows(dataclasses.replace(tables, eval={**tables.eval, "episodes": 0}))
        # a budget's range is checked on each row's planner under it (top_k <= num_candidates)
        wide = {"64x3": {"top_k": 100}}
        with pytest.raises(
            ConfigError, match="tables.mpc_budgets.64x3.top_k: got 100, expected at most num_c"
        ):
            check_rows(dataclasses.replace(tables, mpc_budgets=wide))
    assert list(tmp_path.iterdir()) == []


def test_train_refuses_before_collecting(tmp_path: Path) -> None:
    cfg = compose_config("+exp=smoke", f"data.root={tmp_path / 'data'}", "trainer.steps=abc")
    with pytest.raises(ConfigError, match="trainer.steps: got 'abc', expected an integer"):
        train.run(cfg, tmp_path / "run")
    assert not (tmp_path / "data").exists() and not (tmp_path / "run").exists()


def test_evaluate_refuses_before_loading_a_model(tmp_path: Path) -> None:
    cfg = compose_config(f"checkpoint={tmp_path / 'missing.pt'}", "eval.planner.top_k=65")
    with pytest.raises(ConfigError, match="eval.planner.top_k: got 65"):
        evaluate.evaluate(cfg, tmp_path)  # the missing checkpoint would be the next error


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--top-k", "300", "--candidates", "256"],
            "argument --top-k: got 300, expected at most num_candidates=256",
        ),
        (["--horizon", "0"], "argument --horizon: got 0, expected a positive integer"),
        (["--objective", "teleport"], "argument --objective: invalid choice: 'teleport'"),
        (["--workspace-half-size", "-1"], "argument --workspace-half-size: got -1.0"),
    ],
)
def test_plan_refuses_bad_arguments_before_loading(argv, message, capsys) -> None:
    with pytest.raises(SystemExit):
        plan.parse_args(["--checkpoint", "k.pt", "--image", "a.png", "--goal", "b.png", *argv])
    assert message in capsys.readouterr().err


def test_scene_checks_apply_to_the_env_factory_too() -> None:
    with pytest.raises(ConfigError, match="camera: got 'front', expected one of"):
        make_dm_env(camera="front")
    with pytest.raises(ConfigError, match="num_objects: got 0"):
        SceneSettings(num_objects=0)


def test_values_are_conformed_to_their_annotations() -> None:
    assert conform("lr", 1, float) == 1.0 and isinstance(conform("lr", 1, float), float)
    assert conform("horizons", [1, 3], tuple[int, ...]) == (1, 3)
    assert conform("seed", None, int | None) is None
    for value, annotation in ((True, int), (1.5, int), ("1", float), ("ab", list[str])):
        with pytest.raises(ConfigError, match=f"got {value!r}, expected {describe(annotation)}"):
            conform("key", value, annotation)
    assert describe(tuple[int, ...] | None) == "a list of integers or null"


def test_arguments_are_checked_through_a_keywords_constructor() -> None:
    from kinet_rl.baselines import ImageForwardInverseModel

    # ImageForwardInverseModel(**kwargs) hands its keywords to ImageForwardModel's constructor.
    args = check_arguments(ImageForwardInverseModel, {"feature_dim": 8}, "model")
    assert args["feature_dim"] == 8 and args["num_down"] == 3
    with pytest.raises(ConfigError, match="model.feature_dims: unknown key"):
        check_arguments(ImageForwardInverseModel, {"feature_dims": 8}, "model")


def test_typed_settings_are_what_the_library_gets() -> None:
    settings = ExperimentSettings.from_container(container("trainer.lr=1", "report.horizons=[2]"))
    assert settings.trainer.lr == 1.0 and isinstance(settings.trainer.lr, float)
    assert settings.report.horizons == (2,)

"""One run configuration behind every front door (issue 22, item 3): the demo, bigcbf.run_episode, `bigcbf run`,
the Gymnasium environment and a bare Episode all build their episode from RunConfig() for the same scenario,
method and seed, and one short real episode gives the same metrics through the demo, the API and the CLI."""
from __future__ import annotations

import inspect
import json

import pytest

import bigcbf
from bigcbf.bench.tasks import params_key, params_toml
from bigcbf.cli import main
from bigcbf.cli.demo import DEMO_SCENARIO, demo_episode
from bigcbf.config import RunConfig
from bigcbf.control.route import RouteParams
from bigcbf.episode import DETERMINISTIC_KEYS, Episode
from bigcbf.gym_env import NavigationEnv
from bigcbf.outputs import strict_json
from bigcbf.params.stack import SIMULATION, default_stack_params
from bigcbf.scenario import load_scenario

SEED, SECONDS = 0, 3.0


@pytest.fixture
def built(monkeypatch):
    """The run configuration of every Episode constructed during the test (whichever door built it), as
    (method, RunConfig) rebuilt from the constructor's arguments."""
    seen: list[tuple[str | None, RunConfig]] = []
    init = Episode.__init__
    sig = inspect.signature(init)

    def spy(self, *args, **kwargs):
        init(self, *args, **kwargs)
        a = sig.bind(self, *args, **kwargs)
        a.apply_defaults()
        p = a.arguments
        method = p["method"]
        methods = {} if method is None or p["method_params"] is None else {method: p["method_params"]}
        seen.append((method, RunConfig(stack=self.params, perception=p["perception_params"],
                                       pedestrians=p["pedestrian_params"], methods=methods,
                                       route=p["route"] or RouteParams())))

    monkeypatch.setattr(Episode, "__init__", spy)
    return seen


def _deterministic(metrics: dict) -> dict:
    """The metrics that do not depend on the wall clock, as `bigcbf run --json` prints them."""
    return json.loads(strict_json({k: metrics[k] for k in DETERMINISTIC_KEYS}))


def test_the_default_is_the_calibrated_stack_not_table_one_alone():
    # the premise of the comparisons below: a door that used Table I alone would differ from RunConfig()
    assert RunConfig().stack == default_stack_params()
    assert RunConfig().stack != SIMULATION
    assert params_key(params_toml(RunConfig()), "lidar") != params_key(params_toml(SIMULATION), "lidar")


def test_every_front_door_builds_the_same_configuration_and_the_same_episode(built, capsys):
    want = params_key(params_toml(RunConfig()), "lidar")

    demo_metrics = demo_episode("big-cbf", SEED, time_limit_s=SECONDS).run().metrics()
    api_metrics = bigcbf.run_episode(DEMO_SCENARIO, "big-cbf", SEED, time_limit_s=SECONDS).metrics()
    assert main(["run", DEMO_SCENARIO, "--method", "big-cbf", "--seed", str(SEED), "--time-limit", str(SECONDS),
                 "--json"]) == 0
    cli_metrics = json.loads(capsys.readouterr().out)
    env = NavigationEnv(DEMO_SCENARIO, time_limit_s=SECONDS)
    try:
        env.reset(seed=SEED)
    finally:
        env.close()
    Episode(load_scenario(DEMO_SCENARIO, SEED), "big-cbf", SEED, time_limit_s=SECONDS)    # a bare Episode

    assert [m for m, _ in built] == ["big-cbf", "big-cbf", "big-cbf", None, "big-cbf"]
    default = RunConfig()
    for method, cfg in built:
        assert cfg.stack == default.stack_for(method), method     # with a shipped tuned file: the method's keys
        if method is not None:
            assert cfg.method_params(method) == default.method_params(method), method
        assert cfg.perception == default.perception and cfg.pedestrians == default.pedestrians
        if not default.method_stacks:          # no tuned file: the whole configuration's key too
            assert params_key(params_toml(cfg), "lidar") == want, method
    # one short real episode: the same result through the demo's code path, the API and the command line
    assert _deterministic(demo_metrics) == _deterministic(api_metrics) == _deterministic(cli_metrics)
    assert demo_metrics["sim_time_s"] == pytest.approx(SECONDS, abs=0.1) or demo_metrics["success"]

"""The equal-budget tuning protocol (issue 24, item 4): the shipped grid is valid and was made by its rule, a broken
grid is one line naming the file and the field, and a tiny real search writes its results and a run configuration
that loads."""
from __future__ import annotations

import csv
import json
import re

import pytest

from bigcbf import worlds
from bigcbf.bench import tuning
from bigcbf.bench.tuning import BUDGET, GRID, design, load_grid
from bigcbf.cli import main
from bigcbf.config import RunConfig, load_run_config
from bigcbf.control.methods import METHODS
from bigcbf.errors import UserError

#: the nine methods tuned on their own (big-cbf-noshared takes big-cbf's choice)
TUNED = {"big-cbf", "big-cbf-plus", "cbf-only", "dpcbf", "backup-cbf", "pl-cbf", "apf", "dwa", "mppi"}


def test_shipped_grid_is_the_protocol():
    g = load_grid()
    assert set(g.methods) == TUNED
    assert g.methods["big-cbf"].shared_by == ("big-cbf-noshared",)
    assert set(g.methods) | {"big-cbf-noshared"} == set(METHODS.names())     # every registered method is covered
    # the subset: all families, the first 6 seeds of their dev split, never a test seed
    assert g.split == "dev" and g.families == tuple(worlds.FAMILIES.names())
    for fam in g.families:
        dev = worlds.FAMILIES.get(fam).splits["dev"]
        assert list(g.world_seeds) == list(dev)[:6]
        assert not set(g.world_seeds) & set(worlds.FAMILIES.get(fam).splits.get("test", ()))
    from bigcbf.config import untuned
    base = untuned()                      # the authors' defaults (RunConfig() is the tuned one once it is shipped)
    for name, mg in g.methods.items():
        assert len(mg.configs) == BUDGET and len(set(mg.configs)) == BUDGET
        assert mg.configs[0] == tuple(p.default for p in mg.params)           # the authors' defaults included
        assert list(mg.configs[1:]) == design(mg.params, BUDGET - 1, g.design_seed, name)   # the fixed design
        for p in mg.params:
            assert p.source.strip() and p.lo <= p.default <= p.hi
            assert tuning._code_value(base, name, p.name) == pytest.approx(p.default)
        for i, row in enumerate(mg.configs):
            assert all(p.lo <= v <= p.hi for p, v in zip(mg.params, row))
            rc = tuning.run_config(g, mg, i)                                  # what the episodes run
            for p, v in zip(mg.params, row):
                assert tuning._code_value(rc, name, p.name) == pytest.approx(v)
                for other in mg.shared_by:
                    assert tuning._code_value(rc, other, p.name) == pytest.approx(v)


def test_design_is_a_latin_hypercube():
    """Each parameter's 7 values lie one in each of 7 equal strata of its range (log strata for log parameters),
    up to the rounding to 3 significant digits; the same seed gives the same design, another seed another."""
    import math
    g = load_grid()
    for name, mg in g.methods.items():
        rows = design(mg.params, 7, g.design_seed, name)
        assert rows == design(mg.params, 7, g.design_seed, name) != design(mg.params, 7, g.design_seed + 1, name)
        for j, p in enumerate(mg.params):
            f = (lambda x: math.log(x / p.lo) / math.log(p.hi / p.lo)) if p.scale == "log" else \
                (lambda x: (x - p.lo) / (p.hi - p.lo))
            tol = 0.5 / (p.hi - p.lo) if p.integer else 0.01
            for k, u in enumerate(sorted(f(r[j]) for r in rows)):
                assert k / 7 - tol <= u <= (k + 1) / 7 + tol, (name, p.name)


def _mutated(tmp_path, old: str, new: str, count: int = 1) -> str:
    text = GRID.read_text()
    text2, n = re.subn(old, new, text, count=count, flags=re.M)
    assert n >= 1, old
    p = tmp_path / "grid.toml"
    p.write_text(text2)
    return str(p)


@pytest.mark.parametrize("old, new, field, words", [
    (r"^configs_per_method = 8", "configs_per_method = 6", "protocol.configs_per_method", "8 configurations"),
    (r'^split = "dev"', 'split = "test"', "subset.split", "dev split only"),
    (r"^world_seeds = \[0, 1", "world_seeds = [1000, 1", "subset.world_seeds", "not in posts's dev split"),
    (r"^  \[1\.5\],   # 0: the defaults", "  [1.4],   # 0: the defaults", "methods.cbf-only.configs[0]", "defaults"),
    (r"^  \[0\.648\],   # 1\n", "", "methods.cbf-only.configs", "7 configurations"),
    (r"^  \[0\.648\],", "  [9.5],", "methods.cbf-only.configs[1]", "outside its range"),
    (r"^\[methods\.cbf-only\]", "[methods.cbf-onlyy]", "methods.cbf-onlyy", "not a registered method"),
    (r'^name = "method\.w_heading"', 'name = "method.w_headings"', "methods.dwa", "w_headings"),
])
def test_broken_grid_is_one_line(tmp_path, old, new, field, words):
    path = _mutated(tmp_path, old, new)
    with pytest.raises(UserError) as exc:
        load_grid(path)
    msg = str(exc.value)
    assert path in msg and field in msg and words in msg and "\n" not in msg


def test_tiny_real_search(tmp_path, capsys):
    """1 method, 2 configurations, 1 world cut to 3 s: real episodes through the bench's machinery."""
    out = tmp_path / "tune"
    args = ["tune", "--out", str(out), "--methods", "cbf-only", "--configs", "0", "4", "--families", "posts",
            "--world-seeds", "0", "--time-limit", "3", "--workers", "1", "--progress", "off"]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "cbf-only" in printed and "tuned.toml" in printed
    rows = list(csv.DictReader((out / "tuning.csv").open()))
    assert [(r["method"], r["config"]) for r in rows] == [("cbf-only", "0"), ("cbf-only", "4")]
    assert all(r["episodes"] == "1" and r["ok"] == "1" and r["errors"] == "0" for r in rows)
    assert sum(r["chosen"] == "1" for r in rows) == 1 and rows[0]["params_hash"] != rows[1]["params_hash"]
    res = json.loads((out / "tuning.json").read_text())
    assert res["complete_protocol"] is False and res["grid_sha"] == load_grid().sha
    chosen = res["methods"]["cbf-only"]["chosen"]
    cfg = res["methods"]["cbf-only"]["configs"][[0, 4].index(chosen)]
    assert cfg["success_ci95_pct"] is not None and (cfg["mean_time_to_goal_s"] is None) == (cfg["successes"] == 0)
    text = (out / "tuned.toml").read_text()
    assert "grid.toml sha256 " + res["grid_sha"] in text and "not for shipping" in text
    tuned = load_run_config(out / "tuned.toml")                  # what bench/run --config read
    alpha = load_grid().methods["cbf-only"].configs[chosen][0]
    assert tuned.stack_for("cbf-only").alpha_per_s == alpha and tuned.stack.alpha_per_s == RunConfig().stack.alpha_per_s
    # each configuration's episodes ran with its own parameters (the stored run configurations)
    import sqlite3
    with sqlite3.connect(out / "results.sqlite") as db:
        stored = {h: t for h, t in db.execute("SELECT params_hash, toml FROM params")}
    assert "alpha_per_s = 2.59" in stored[rows[1]["params_hash"]]
    # a rerun resumes: nothing runs again
    res2 = tuning.run_tuning(load_grid(), out, ["cbf-only"], 1, configs=[0, 4], progress=False, families=["posts"],
                             world_seeds=[0], time_limit_s=3.0, log=lambda m: None)
    assert res2["run"]["ran"] == 0 and res2["methods"]["cbf-only"]["chosen"] == chosen
    # a slice is never shipped
    with pytest.raises(UserError, match="slice"):
        tuning.write_shipped(out, load_grid())
    _shipped_file_is_the_default(out / "tuned.toml", alpha)


def _shipped_file_is_the_default(tuned_file, alpha):
    """A shipped tuned file (here the tiny search's, in place of bigcbf/params/tuning/tuned.toml) gives RunConfig()
    -- every front door -- its methods' defaults; untuned() stays at the authors' defaults."""
    from bigcbf import config
    from bigcbf.params.stack import default_stack_params

    old = config.TUNED_PATH
    config.shipped_tuned.cache_clear()
    try:
        config.TUNED_PATH = tuned_file
        assert RunConfig().stack_for("cbf-only").alpha_per_s == alpha
        assert RunConfig().stack_for("big-cbf") == default_stack_params()
        assert config.untuned().stack_for("cbf-only").alpha_per_s == default_stack_params().alpha_per_s
        assert "grid.toml sha256" in config.tuned_provenance()
        from bigcbf.api import load_config
        notes = []
        assert load_config(notes=notes.append).stack_for("cbf-only").alpha_per_s == alpha
        assert len(notes) == 1 and "grid.toml sha256" in notes[0] and "defaults.toml" in notes[0]
        bad = tuned_file.parent / "bad_tuned.toml"
        bad.write_text("[stack]\nalpha_per_s = 2.0\n")
        config.TUNED_PATH = bad
        config.shipped_tuned.cache_clear()
        with pytest.raises(UserError, match="bad_tuned.toml.*methods.NAME"):
            RunConfig()
    finally:
        config.TUNED_PATH = old
        config.shipped_tuned.cache_clear()


@pytest.mark.parametrize("extra, words", [
    (["--configs", "8"], "numbered 0-7"),
    (["--methods", "big-cbf-noshared"], "not in the tuning grid"),
    (["--world-seeds", "6"], "not in the tuning subset"),
    (["--families", "nowhere"], "not in the tuning subset"),
])
def test_bad_arguments_are_one_line(tmp_path, capsys, extra, words):
    assert main(["tune", "--out", str(tmp_path / "o")] + extra) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1


def test_shipped_defaults_file_is_the_authors_defaults():
    """bigcbf/params/tuning/defaults.toml is made from the grid and runs every method as untuned() does."""
    from bigcbf.config import untuned
    g = load_grid()
    assert tuning.DEFAULTS.read_text() == tuning.defaults_toml(g)
    cfg, base = load_run_config(tuning.DEFAULTS, base=untuned()), untuned()
    for m in METHODS.names():
        assert cfg.stack_for(m) == base.stack_for(m) and cfg.method_params(m) == base.method_params(m)


def test_write_shipped_needs_the_whole_protocol(tmp_path, monkeypatch):
    """--write-shipped copies a search's files only when they hold the whole protocol of the grid as it is now, with
    a choice for every method (the search's own files stand in here: the whole protocol is thousands of episodes)."""
    g = load_grid()
    out = tmp_path / "search"
    out.mkdir()
    res = {"complete_protocol": True, "grid_sha": g.sha, "methods": {m: {"chosen": 0} for m in g.methods}}
    for name in tuning.SHIPPED:
        (out / name).write_text(f"{name} of the search\n")
    dest = {name: tmp_path / "shipped" / f"results_{name}" for name in tuning.SHIPPED}
    monkeypatch.setattr(tuning, "SHIPPED", dest)

    def ship(**changes):
        (out / "tuning.json").write_text(json.dumps({**res, **changes}))
        return tuning.write_shipped(out, g)

    with pytest.raises(UserError, match="grid is now " + g.sha):
        ship(grid_sha="0" * 16)
    with pytest.raises(UserError, match="no choice for dwa"):
        ship(methods={**res["methods"], "dwa": {"chosen": None}})
    with pytest.raises(UserError, match="slice"):
        ship(complete_protocol=False)
    assert not any(p.exists() for p in dest.values())
    assert sorted(ship()) == sorted(dest.values())
    assert all(dest[n].read_text() == (out / n).read_text() for n in tuning.SHIPPED)


def test_tuned_defaults_note_follows_a_success_only(tmp_path, capsys, monkeypatch):
    """With a tuned file shipped, a command that fails prints its one error line and nothing else; one that
    succeeds ends with the note naming the tuned defaults' provenance (cli.run.config_note)."""
    from bigcbf import config
    from bigcbf.cli import main
    tuned = tmp_path / "tuned.toml"
    tuned.write_text("# Provenance: grid grid.toml sha256 0123; code git abc\n[methods.cbf-only.stack]\n"
                     "alpha_per_s = 2.0\n")
    monkeypatch.setattr(config, "TUNED_PATH", tuned)
    config.shipped_tuned.cache_clear()
    try:
        assert main(["run", "no_such_scenario", "--method", "cbf-only"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "error" in err[0] and "no_such_scenario" in err[0]
        assert main(["run", "required_sidestepping", "--method", "cbf-only", "--time-limit", "0.5", "--json"]) == 0
        err = capsys.readouterr().err
        assert "note: method defaults: the tuned configuration tuned.toml (Provenance: grid grid.toml sha256 0123" in err
        # with --config the note says the file is read over the tuned values, not that those are the defaults
        own = tmp_path / "own.toml"
        own.write_text("[methods.cbf-only.stack]\nalpha_per_s = 1.5\n")
        assert main(["run", "required_sidestepping", "--method", "cbf-only", "--time-limit", "0.5", "--json",
                     "--config", str(own)]) == 0
        err = capsys.readouterr().err
        assert "method defaults" not in err and f"note: {own}: read over the tuned configuration tuned.toml" in err
    finally:
        config.shipped_tuned.cache_clear()

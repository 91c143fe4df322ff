"""Training a run's learned configurations (`registry.StrategySpec.fit`, `train=START..END`)
with the study runner itself, inside the run folder (layout: docs/CONTRACTS.md):

    RUN/train/reference/    the AC OPF (the reference optimum), no action and the run's
                            other local rules over the training period: a run folder of its
                            own (checkpointed, resumable), k ∈ {TRAIN_K} ∪ the run's k, PV
                            connected at night, forecast off, with the per-DER Q table
    RUN/learned/<case>--<label>.json
                            each learned configuration fitted to the optimum at TRAIN_K on
                            each case model (`LearnedParams`; the names' characters other
                            than letters and digits as '-')
    RUN/train/learned/      the learned configurations (and no action) over the training
                            period: their in-sample figures (no per-DER table)
    RUN/train/summary.csv   both runs' summaries: the report's training-period column

The cases trained on are the run's case models (`learning.model_case`: a `line-z`
perturbed case is fitted on its unperturbed model). A fitted file is reused (a resume)
only when the folder's manifests recorded it — its sha256, as the case data's — and its
training data (their hash) and fit options are those of the run; a file that differs from
the recorded one (edited by hand) is refused, one never recorded is fitted again. The fitted rules reach the run's tasks as `Fitted` records: the parameters' text
travels with each task (a worker needs no access to the run folder), and their hashes are
part of the run's configuration, so a refit is another configuration.
"""

from __future__ import annotations

import io
import json
import re
from dataclasses import replace
from functools import lru_cache, partial
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from opfbench.errors import InputError
from opfbench.formulations.frontier import tightened
from opfbench.io import load_network
from opfbench.jsonio import write_atomic
from opfbench.learned.fitted import LEARNED_DIR, TRAIN_DIR, Fitted
from opfbench.learned.rules import TRAIN_K, TRAIN_NIGHT, LearnedParams
from opfbench.registry.catalog import configuration, is_formulation
from opfbench.registry.references import BASELINE, REFERENCE_OPTIMUM
from opfbench.study.training_checks import LearnedConfig, learned_configs, model_case, training_set

TRAIN_SUMMARY = f"{TRAIN_DIR}/summary.csv"


NestedRun = Callable[[Any, Path, tuple[Fitted, ...]], Any]
"""Runs a study config into a folder with the given fitted rules and returns the finished
run (its `summary`): the runner's `run_study`, with the run's workers and scheduler."""


def given(labels: tuple[str, ...], cases: tuple[str, ...]) -> list[Fitted]:
    """The `params=FILE` configurations' rules for every case (checked by `check_learned`)."""
    from opfbench.learned.rules import load_params

    return [
        Fitted.of(case, lc.label, lc.params, load_params(lc.params))
        for lc in learned_configs(labels)
        if lc.params
        for case in cases
    ]


def recorded_fits(out: Path) -> dict[str, str]:
    """The sha256 of each fitted rule (by its ref, `learned/<file>.json`) that the run
    folder `out`'s manifests recorded: the run's own and its in-sample training run's."""
    recorded: dict[str, str] = {}
    for manifest in (out / TRAIN_DIR / "learned" / "manifest.json", out / "manifest.json"):
        try:
            config = json.loads(manifest.read_bytes().decode("utf-8")).get("config")
        except (OSError, ValueError, AttributeError):
            continue
        for fit in config.get("fitted", []) if isinstance(config, dict) else []:
            if isinstance(fit, dict) and isinstance(fit.get("ref"), str) and isinstance(fit.get("sha256"), str):
                recorded[fit["ref"]] = fit["sha256"]
    return recorded


def train(config: Any, out: Path, run_nested: NestedRun, recorded: dict[str, str] | None = None) -> tuple[Fitted, ...]:
    """Fit the `train=` configurations of the study `config` into the run folder `out`
    (module docstring); returns every learned configuration's rules for the run's cases.
    `recorded`: the fitted rules' sha256 by ref that the folder's run recorded
    (`recorded_fits`; none: fit every rule anew)."""
    fitted = given(config.strategies, config.cases)
    trained = [lc for lc in learned_configs(config.strategies) if lc.train]
    if not trained:
        return tuple(fitted)
    period = trained[0].train
    models = tuple(dict.fromkeys(model_case(case) for case in config.cases))
    common = {
        "cases": models,
        "night_modes": (TRAIN_NIGHT,),
        "night": config.night,
        "forecast": ("off",),
        "period": period,
        "step_minutes": config.step_minutes,
        "chunk": config.chunk,
        "acopf_solver": config.acopf_solver,
        "forecast_dir": config.forecast_dir,
    }
    others = [s for s in config.strategies if not is_formulation(s) and not configuration(s).spec.learned and s != BASELINE]
    reference = type(config).build(
        strategies=[BASELINE, REFERENCE_OPTIMUM, *others], ks=sorted({TRAIN_K, *config.ks}), detail=("der_q",), **common
    )
    ref_run = run_nested(reference, out / TRAIN_DIR / "reference", ())
    (out / LEARNED_DIR).mkdir(exist_ok=True)
    on_models: list[Fitted] = []
    for model in models:
        q, ok = optimum(ref_run.out, model, len(load_network(model).ders))
        training = training_set(model, period, config.night, q, ok, config.step_minutes)
        training = replace(training, tightened=lru_cache(partial(tightened, training.scenario, TRAIN_K, q_mvar=q, ok=ok)))
        for lc in trained:
            path = out / LEARNED_DIR / f"{_stem(model)}--{_stem(lc.label)}.json"
            ref = f"{LEARNED_DIR}/{path.name}"
            params = _fit(lc, training, path, (recorded or {}).get(ref))
            on_models.append(Fitted.of(model, lc.label, ref, params))
            fitted += [Fitted.of(case, lc.label, ref, params) for case in config.cases if model_case(case) == model]
    in_sample = type(config).build(strategies=[BASELINE, *(lc.label for lc in trained)], ks=config.ks, detail=False, **common)
    learned_run = run_nested(in_sample, out / TRAIN_DIR / "learned", tuple(on_models))
    ref_summary = ref_run.summary[ref_run.summary["k"].isin(config.ks)]
    rows = learned_run.summary[learned_run.summary["strategy"] != BASELINE]
    buf = io.StringIO()
    pd.concat([ref_summary, rows], ignore_index=True).to_csv(buf, index=False, float_format="%.6g")
    write_atomic(out / TRAIN_SUMMARY, buf.getvalue())
    return tuple(fitted)


def _stem(text: str) -> str:
    """`text` as a file name's part: letters and digits, every other run of characters '-'."""
    return re.sub(r"[^A-Za-z0-9]+", "-", text).strip("-")


def _fit(lc: LearnedConfig, training, path: Path, recorded: str | None) -> LearnedParams:
    """The fitted rule of `lc` on `training`: the file at `path` where the run recorded it
    (its sha256 `recorded`) and it was fitted to the same data with the same options, else
    fitted now and written there. InputError for a file that is not the one recorded."""
    spec = configuration(lc.label).spec
    if path.exists() and recorded is not None:
        try:
            kept: LearnedParams | None = LearnedParams.parse(path.read_text(encoding="utf-8"), str(path))
        except (InputError, OSError, UnicodeDecodeError):
            kept = None
        if kept is None or kept.digest != recorded:
            now = "unreadable" if kept is None else f"{kept.digest[:12]}…"
            raise InputError(
                f"{path}: the fitted rule is not the one this run fitted and recorded (sha256 {recorded[:12]}… → {now}); "
                "its figures would change under the same label: restore the file, or use --fresh to fit it again"
            )
        if kept.data_sha256 == training.digest() and kept.family == spec.name:
            fresh_options = {"rho": lc.options["rho"], "hyper": _hyper(lc.options)}
            if kept.rho == fresh_options["rho"] and kept.hyper == fresh_options["hyper"]:
                return kept
    params = spec.fit_rule(training, lc.options)
    params.write(path)
    return params


def _hyper(options: dict) -> dict:
    """The fit's hyper-parameters as `LearnedParams.hyper` records them."""
    return ({"knots": options["knots"]} if "knots" in options else {}) | {
        "rounds": options["rounds"],
        "comply": options["comply"],
    }


def optimum(folder: Path, case: str, n_der: int) -> tuple[np.ndarray, np.ndarray]:
    """(Q (S, n_der) MVAr, ok (S,)) of the reference optimum at TRAIN_K, PV connected at
    night, forecast off, in the run folder `folder` (its der_q.parquet and steps.parquet)."""
    import pyarrow.parquet as pq

    keys = [
        ("case", "==", case),
        ("strategy", "==", REFERENCE_OPTIMUM),
        ("k", "==", TRAIN_K),
        ("night_mode", "==", TRAIN_NIGHT),
        ("forecast", "==", "off"),
    ]
    der_q = pq.read_table(folder / "der_q.parquet", columns=["time", "q_mvar"], filters=keys).to_pandas()
    steps = pq.read_table(folder / "steps.parquet", columns=["time", "status"], filters=keys).to_pandas()
    steps = steps.sort_values("time", kind="stable")
    q = der_q.sort_values("time", kind="stable")["q_mvar"].to_numpy()
    if q.size != len(steps) * n_der:
        raise InputError(f"{folder}: the optimum's per-DER Q table has {q.size} rows; {len(steps)} steps × {n_der} DER expected")
    return q.reshape(len(steps), n_der), (steps["status"] == "ok").to_numpy()

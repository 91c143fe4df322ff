"""Learned rules in a study (`registry.StrategySpec.fit`): their training periods, kept
apart from the test period, and the training data.

A learned configuration names where its parameters come from: `train=START..END` (half
open, END excluded, like `--period`) is fitted by the run to the AC OPF over that period,
or `params=FILE` is a rule fitted elsewhere. Either way its training period must not
overlap the run's test period (it may end where the test begins): a rule is tested on
steps it has not seen. Everything here is checked before any work.

The training data of a case are those of the case's model (`CaseSpec.model`: without its
`line-z` perturbation — the operator fits on the grid as modelled) over the training
period, at the case's own step, PV connected at night, no forecast, k = TRAIN_K: the
scenario the study's own tasks would build for that period (`chunk_scenario`), so the
optimum the run computes over it belongs to exactly these snapshots.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from opfbench.errors import InputError
from opfbench.io import load_network, parse_spec
from opfbench.learned.rules import TRAIN_NIGHT, TrainingSet, check_samples, family_rule, load_params, usable
from opfbench.registry.catalog import configuration
from opfbench.scenario import Scenario
from opfbench.study.periods import Period, local_time

Window = tuple[pd.Timestamp, pd.Timestamp]  # [start, end), local time


@dataclass(frozen=True)
class LearnedConfig:
    """A learned configuration of a run: its canonical `label`, its full `options`, and
    `train` (the training period to fit over) or `params` (the file it was fitted to)."""

    label: str
    options: dict
    train: str
    params: str


def learned_configs(labels: tuple[str, ...]) -> list[LearnedConfig]:
    """The learned configurations among `labels`, in order."""
    out = []
    for label in labels:
        config = configuration(label)
        if config.spec.learned:
            options = config.options()
            out.append(LearnedConfig(config.label, options, str(options["train"]), str(options["params"])))
    return out


def train_window(text: str, label: str) -> Window:
    """The training period `START..END` as [start, end) in local time; InputError naming
    the label otherwise."""
    first, sep, last = text.partition("..")
    if not sep:
        raise InputError(f"{label}: train must be a period START..END (END excluded), got {text!r}")
    start, end = local_time(first, f"{label}: train"), local_time(last, f"{label}: train")
    if end <= start:
        raise InputError(f"{label}: train {text}: END must come after START")
    return start, end


def test_window(period: Period) -> Window:
    """The run's period as [first step, last step + one step)."""
    return period.index[0], period.index[-1] + pd.Timedelta(hours=period.step_h)


def check_disjoint(label: str, train: Window, test: Window, test_label: str) -> None:
    """InputError when the training period overlaps the test period (half-open windows)."""
    if train[0] < test[1] and test[0] < train[1]:
        raise InputError(
            f"{label}: the training period {train[0].isoformat()} .. {train[1].isoformat()} overlaps the test period "
            f"{test_label} ({test[0].isoformat()} .. {test[1].isoformat()}, END excluded); a rule must be tested on steps "
            "it was not fitted on — train on an earlier or later period (it may end where the test begins)"
        )


def model_case(case: str) -> str:
    """The spec of the case a learned rule is fitted on: `case` as modelled (no `line-z`)."""
    return parse_spec(case).model.text


def check_learned(
    labels: tuple[str, ...], cases: tuple[str, ...], period: Period, night: str, step_minutes: float | None = None
) -> None:
    """Every learned configuration's training period apart from the test period, with
    enough samples for every DER of every case model (`check_training_samples`), and a
    params file fitted on the cases it runs on (`check_params`); InputError otherwise."""
    test = test_window(period)
    trained = sorted({lc.train for lc in learned_configs(labels) if lc.train})
    if len(trained) > 1:
        raise InputError(
            f"the learned configurations of a run share one training period (the report's training column); got "
            f"{', '.join(trained)}: run them separately"
        )
    for lc in learned_configs(labels):
        if lc.train:
            check_disjoint(lc.label, train_window(lc.train, lc.label), test, period.label)
            continue
        params = load_params(lc.params)
        check_disjoint(lc.label, train_window(str(params.train.get("period")), lc.label), test, period.label)
    check_params(labels, cases)
    check_training_samples(labels, cases, night, step_minutes)


def check_params(labels: tuple[str, ...] | list[str], cases: tuple[str, ...] | list[str]) -> None:
    """Every `params=FILE` configuration among `labels` was fitted on the model of each of
    `cases` (`LearnedParams.check_network`: its DER and its whole grid; a `line-z`
    perturbed case runs on its model's rule); InputError naming the file otherwise."""
    for lc in learned_configs(tuple(labels)):
        if lc.params:
            params = load_params(lc.params)
            for case in cases:
                params.check_network(load_network(model_case(case)), lc.params)


def check_training_samples(labels: tuple[str, ...], cases: tuple[str, ...], night: str, step_minutes: float | None) -> None:
    """Before any work: every DER of every case model has a reactive limit at enough steps
    of the training period to fit each `train=` configuration (`learned.check_samples`; the
    fit checks again with the optimum's certified steps); InputError naming the DER."""
    trained = [lc for lc in learned_configs(labels) if lc.train]
    for model in dict.fromkeys(model_case(case) for case in cases) if trained else ():
        _, scenario = training_scenario(model, trained[0].train, night, step_minutes)
        samples = usable(scenario).sum(axis=0)
        for lc in trained:
            rule = family_rule(configuration(lc.label).spec.name, lc.options)
            check_samples(rule, scenario.net, samples, f"{model} over {lc.train} (steps where it has a reactive limit)")


def training_scenario(case: str, train: str, night: str, step_minutes: float | None = None) -> tuple[Period, Scenario]:
    """The training period and snapshots of the case `case` (its own spec; `model_case`
    gives a perturbed case's model) over `train` (at `step_minutes`, default the case's
    own step): PV connected at night, no forecast."""
    from opfbench.study.task_scenarios import chunk_scenario, study_period

    period, _ = study_period((case,), ("off",), train, night, step_minutes)
    step = pd.Timedelta(hours=period.step_h)
    return period, chunk_scenario(case, TRAIN_NIGHT, "off", period.profiles, period.night, len(period.index), step, "")


def training_set(
    case: str, train: str, night: str, q_mvar: np.ndarray, ok: np.ndarray, step_minutes: float | None = None
) -> TrainingSet:
    """The training set of `case` over `train` with the optimum `q_mvar` (S, n_der) and its
    certified steps `ok` (S,)."""
    period, scenario = training_scenario(case, train, night, step_minutes)
    if q_mvar.shape != scenario.der_p_mw.shape or ok.shape != (scenario.n_snapshots,):
        raise InputError(
            f"{case}: the optimum over {train} has shape {q_mvar.shape}; the training period has "
            f"{scenario.der_p_mw.shape} (steps, DER)"
        )
    return TrainingSet(case, train, period.index[0].isoformat(), period.index[-1].isoformat(), scenario, q_mvar, ok)

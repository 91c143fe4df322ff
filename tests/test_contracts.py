"""docs/CONTRACTS.md is what the commands write: a fresh run folder, fault folder and
forecast folder hold exactly the documented files, each table exactly the documented
columns (names, order, kinds) and each JSON file exactly the documented fields — and the
check itself sees a column or a field added, renamed or dropped."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from opfbench import schema
from opfbench.cli import main
from opfbench.study.run_tables import extra_columns
from tests.support.contracts import DOC, check_folder, check_json, check_table, parse
from tests.support.forecast_synthetic import use_tiny_synthetic

CONTRACT = parse()
LEARNED = "learned-affine:train=2016-06-27T10:00..2016-06-27T11:00"  # its training writes learned/ and train/
RUN = ["run", "--period", "2016-06-28T10:00..2016-06-28T10:20", "--strategies", "no-action", "volt-var", LEARNED, "--k", "0"]
RUN += ["--night-modes", "connected", "--forecast", "off", "--detail", "--workers", "1", "--quiet"]
FAULT = ["fault", "paper33", "--fault-bus", "18", "--strategies", "no-action", "--k", "0", "--t-end", "0.4"]
FAULT += ["--workers", "1", "--quiet"]


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("contract") / "run"
    assert main([*RUN, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def fault_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("contract") / "fault"
    assert main([*FAULT, "--out", str(out)]) == 0
    return out


def test_the_page_declares_every_folder_file_and_block():
    assert set(CONTRACT.files) == {"run", "fault", "forecast"}
    assert {"steps.parquet", "summary.csv", "tasks/<id>.summary.parquet"} <= {f for _, f in CONTRACT.columns}
    assert set(CONTRACT.blocks) == {"timings", "model", "fault"}
    assert ("run", "manifest.json") in CONTRACT.fields and ("fault", "manifest.json") in CONTRACT.fields


def test_the_page_and_the_schema_cannot_disagree(monkeypatch):
    """Every table `opfbench.schema` declares is on the page exactly as the schema writes
    it (name, type, unit, meaning, in order) — regenerate with `python -m opfbench.schema
    docs/CONTRACTS.md` — and the check sees a declaration the page does not have."""
    text = DOC.read_text(encoding="utf-8")
    assert schema.contracts_page(text) == text, (
        "docs/CONTRACTS.md differs from opfbench.schema: python -m opfbench.schema docs/CONTRACTS.md"
    )
    for folder, tables in schema.TABLES.items():
        for table in tables:
            extra = ["<extra>"] if table.extra is not None else []
            assert [name for name, _ in CONTRACT.columns[(folder, table.file)]] == table.names + extra, table.file
    added = schema.Table(schema.STEPS.file, (*schema.STEPS.columns, schema.Column("vuf_pct", "number", "%", "a new one")))
    monkeypatch.setitem(schema.TABLES, "run", (added, *schema.TABLES["run"][1:]))
    assert schema.contracts_page(text) != text


def test_a_fresh_run_folder(run_folder):
    extra = list(extra_columns(("no-action", "volt-var", LEARNED)))
    assert extra == ["residual_mvar"]  # a closed-loop rule's column
    assert check_folder(CONTRACT, "run", run_folder, {"<extra>": extra}) == []


def test_a_fresh_fault_folder(fault_folder):
    assert check_folder(CONTRACT, "fault", fault_folder) == []


def test_a_fresh_forecast_folder(tmp_path, monkeypatch, capsys):
    use_tiny_synthetic(monkeypatch)
    models = ["persistence", "arima", "lstm"]
    assert main(["forecast", "--dataset", "pv", "--quick", "--models", ",".join(models), "--out", str(tmp_path)]) == 0
    assert check_folder(CONTRACT, "forecast", tmp_path, {"<model>": models}) == []


def test_the_check_sees_a_column_added_renamed_or_dropped(run_folder, tmp_path):
    steps = pd.read_parquet(run_folder / "steps.parquet")
    for name, frame in (
        ("added", steps.assign(extra_kw=1.0)),
        ("renamed", steps.rename(columns={"losses_kw": "loss_kw"})),
        ("dropped", steps.drop(columns="night")),
        ("retyped", steps.assign(power_flows=steps.power_flows.astype(float))),
    ):
        frame.to_parquet(tmp_path / f"{name}.parquet", index=False)
        assert check_table(CONTRACT, "run", "steps.parquet", tmp_path / f"{name}.parquet", {"<extra>": ["residual_mvar"]}), name
    summary = pd.read_csv(run_folder / "summary.csv")
    summary.rename(columns={"gap_pct": "gap_percent"}).to_csv(tmp_path / "summary.csv", index=False)
    assert check_table(CONTRACT, "run", "summary.csv", tmp_path / "summary.csv")


def test_the_check_sees_a_field_added_renamed_or_dropped(fault_folder, tmp_path):
    manifest = json.loads((fault_folder / "manifest.json").read_text())
    edits = {
        "added": lambda m: m["timings"].update(extra=1),
        "renamed": lambda m: m["recovery"].update(threshold=m["recovery"].pop("threshold_pu")),
        "dropped": lambda m: m["tasks"][0]["definition"].pop("q_mvar"),
        "in a block": lambda m: m["variants"]["reference"]["motors"].pop("h_s"),
        "retyped": lambda m: m.update(schema="2"),
    }
    for name, edit in edits.items():
        edited = json.loads(json.dumps(manifest))
        edit(edited)
        (tmp_path / "manifest.json").write_text(json.dumps(edited))
        assert check_json(CONTRACT, "fault", "manifest.json", tmp_path / "manifest.json"), name
    (fault_folder / "tasks" / "stray.parquet").write_bytes(b"")
    try:
        assert check_folder(CONTRACT, "fault", fault_folder) == ["tasks/stray.parquet: not in CONTRACTS.md (fault folder)"]
    finally:
        (fault_folder / "tasks" / "stray.parquet").unlink()

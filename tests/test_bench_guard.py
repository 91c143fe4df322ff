"""The benchmark record and its regression guard (`python -m opfbench.bench all`, `check`),
on recorded files: `tests/support/bench/` holds records of `all --only pf` — two of the code
as it is, and one of a deliberately slowed power flow (the batched solver run twice), made
with `--tree` on a copy of the tree — so the comparison logic is tested on real records
and nothing here times anything."""

import json
import shutil
from pathlib import Path

import pytest

from opfbench.bench.__main__ import main
from opfbench.bench.check import MISSING, NEW, OK, WORSE, compare
from opfbench.bench.page import page_text
from opfbench.bench.record import ALL, PAGE, RECORD, flatten, medians, read_record

RECORDS = Path(__file__).parent / "support" / "bench"


@pytest.fixture(scope="module")
def records() -> dict[str, dict]:
    return {name: read_record(RECORDS / f"{name}.json") for name in ("pf", "pf-again", "pf-slowed")}


def test_a_deliberately_slowed_power_flow_is_caught(records, capsys):
    verdicts = {v.key: v for v in compare(records["pf-slowed"], records["pf"])}
    assert verdicts["pf.batch_1440_ms"].status == WORSE and verdicts["pf.batch_1440_ms"].change > 0.25
    assert verdicts["pf.single_ms"].status == OK  # Newton–Raphson was not slowed
    assert main(["check", str(RECORDS / "pf-slowed.json"), "--baseline", str(RECORDS / "pf.json")]) == 1
    out = capsys.readouterr().out
    assert "pf.batch_1440_ms" in out and "worse" in out and "1 key(s) more than 25 % worse" in out


def test_two_records_of_the_same_code_pass(records, capsys):
    assert all(v.status == OK for v in compare(records["pf-again"], records["pf"]))
    assert main(["check", str(RECORDS / "pf-again.json"), "--baseline", str(RECORDS / "pf.json"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["flagged"] == []


def test_the_ratio_to_the_peer_is_compared_not_the_time(records):
    """The same run on a machine twice as slow — every time doubled, the peer's too — passes;
    the key alone doubled fails."""
    base = records["pf"]
    slow = json.loads(json.dumps(base))
    slow["keys"] = {k: 2 * v if k.endswith("_ms") else v for k, v in base["keys"].items()}
    assert all(v.status == OK for v in compare(slow, base))
    slow["keys"] = dict(base["keys"]) | {"pf.batch_1440_ms": 1.3 * base["keys"]["pf.batch_1440_ms"]}
    assert {v.key for v in compare(slow, base) if v.status == WORSE} == {"pf.batch_1440_ms"}


def test_a_lost_key_is_flagged_and_a_new_one_is_not(records):
    base, new = records["pf"], json.loads(json.dumps(records["pf"]))
    del new["keys"]["pf.single_ms"]
    new["guards"]["pf.extra_ms"] = "pf.pgm_batch_1440_ms"
    new["keys"]["pf.extra_ms"] = 1.0
    status = {v.key: v.status for v in compare(new, base)}
    assert status["pf.single_ms"] == MISSING and status["pf.extra_ms"] == NEW and status["pf.batch_1440_ms"] == OK


def test_a_file_that_is_no_record_is_refused_with_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert main(["check", str(bad), "--baseline", str(RECORDS / "pf.json")]) == 2
    assert str(bad) in capsys.readouterr().err
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"schema": 1, "keys": {"a": "x"}, "guards": {}, "benches": {}}))
    assert main(["check", str(other), "--baseline", str(RECORDS / "pf.json")]) == 2
    assert "is not a number" in capsys.readouterr().err
    assert main(["check", str(tmp_path / "absent.json")]) == 2


def test_records_hold_medians_of_flattened_figures():
    runs = [{"a": 1.0, "t": {"x": 3}, "s": "text", "ok": True, "l": [1, 2]}, {"a": 3.0, "t": {"x": 5}}, {"a": 2.0}]
    assert flatten(runs[0]) == {"a": 1.0, "t.x": 3.0}
    assert flatten({"cases": [{"ms": 1}, {"ms": 2, "case": "x"}]}) == {"cases.0.ms": 1.0, "cases.1.ms": 2.0}
    assert medians(runs) == {"a": 2.0, "t.x": 4.0}


def test_the_committed_page_is_generated_from_the_committed_record():
    record = read_record(RECORD)
    assert PAGE.read_text() == page_text(record, RECORD)
    guarded = {f"{b.name}.{k}" for b in ALL for k in b.guards}
    assert set(record["guards"]) <= guarded  # no stale guard (a bench added since joins at the next record)
    assert all(record["keys"].get(key) is not None for key in record["guards"])  # every guarded key measured


def test_markdown_writes_the_page_of_a_record(tmp_path):
    record = tmp_path / "r.json"
    shutil.copy(RECORDS / "pf.json", record)
    page = tmp_path / "page.md"
    assert main(["all", "--markdown", "--record", str(record), "--page", str(page)]) == 0
    text = page.read_text()
    assert "pf.batch_1440_ms" in text and "| `pf.batch_1440_ms` |" in text and read_record(record)["commit"][:12] in text

"""The report in headless Chromium (Debian `chromium`) with the network refused: no console
errors, every plot drawn, every section present, no request leaves the page; and the check
itself catches a page that does load remote resources."""

from __future__ import annotations

import os

import pytest

from opfbench.report import write_report
from opfbench.report.browser import check_page, find_chromium
from tests.support.report_folders import write_fault, write_run

SECTIONS = ["claims", "metadata", "losses", "convergence", "night", "gap", "voltage", "forecasting", "fault"]

if find_chromium() is None:
    if os.environ.get("CI", "").lower() == "true":
        raise RuntimeError("CI must provide Chromium: .ci/run installs the Debian package `chromium`")
    pytest.skip("no Chromium binary (install the Debian package `chromium`)", allow_module_level=True)


def test_report_renders_offline_in_chromium(tmp_path):
    case = "<img src=x onerror=alert(1)>.m"
    run = write_run(tmp_path / "run", case=case)
    page = write_report(run, fault_dir=write_fault(tmp_path / "fault", case=case))
    check = check_page(page)
    assert check.errors == []
    assert check.plots >= 10 and check.drawn == check.plots
    assert [s for s in check.sections if s in SECTIONS] == SECTIONS
    assert check.resources == [] and check.page_requests == []
    assert check.images == 0  # the case name is text, not an element


def test_the_check_sees_remote_requests(tmp_path):
    page = tmp_path / "leaky.html"
    page.write_text(
        '<!DOCTYPE html><html><head><script src="https://cdn.example.org/lib.js"></script></head>'
        '<body><img src="http://example.com/x.png"><section id="s"></section></body></html>'
    )
    check = check_page(page)
    assert sorted(check.resources) == ["http://example.com/x.png", "https://cdn.example.org/lib.js"]
    assert len(check.page_requests) == 2 and check.images == 1

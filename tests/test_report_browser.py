"""The report in headless Chromium (Debian `chromium`) with the network refused: no console
errors, every plot drawn, every section present, no request leaves the page; and the check
itself catches a page that does load remote resources."""

from __future__ import annotations

import os

import pytest

from opfbench.report import write_report
from opfbench.report.browser import check_page, find_chromium
from tests.support.report_folders import write_fault, write_run

SECTIONS = ["local", "claims", "metadata", "losses", "grids", "convergence", "year", "field-year", "night", "gap", "voltage"]
SECTIONS += ["forecasting", "fault"]

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


def test_the_screenshot_command_names_a_bad_page_in_one_line(tmp_path, capsys):
    from opfbench.report.screenshot import main as screenshot_main

    missing = tmp_path / "none.html"
    assert screenshot_main([str(missing), str(tmp_path / "out.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert str(missing) in err and len(err.splitlines()) == 1 and not (tmp_path / "out.png").exists()
    page = tmp_path / "page.html"
    page.write_text("<html><body>no head</body></html>")
    assert screenshot_main([str(page), str(tmp_path / "out.png")]) == 2
    assert "has no <head>: not an opfbench page" in capsys.readouterr().err

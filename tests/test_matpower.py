"""MATPOWER reader: the shipped cases parse; every malformed input names what is wrong."""

import numpy as np
import pytest

from opfbench.cases import CASE_NAMES
from opfbench.errors import CaseFormatError, InputError
from opfbench.io import load_network
from opfbench.io.matpower import load_case_file, read_matpower
from tests.support.matpower_texts import TINY_CASE
from tests.support.shipped_cases import SHIPPED


def _write(tmp_path, text, name="broken.m"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_good_file_applies_ohm_and_kw_conversions(tmp_path):
    case = read_matpower(_write(tmp_path, TINY_CASE, "tiny.m"))
    zbase = 12.66**2 / 10
    assert case.branch[0, 2] == pytest.approx(0.0922 / zbase)
    assert case.bus[1, 2] == pytest.approx(0.1) and case.bus[1, 3] == pytest.approx(0.06)
    net = load_case_file(tmp_path / "tiny.m")
    assert list(net.bus_ids) == [1, 2, 3] and net.slack == 0


def test_every_shipped_case_is_pinned():
    assert set(SHIPPED) == set(CASE_NAMES)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_shipped_cases_load(name):
    n_bus, n_branch, in_service, n_der, load_p, load_q, meshed = SHIPPED[name]
    net = load_network(name)
    assert (net.n_bus, net.f.size, int(net.status.sum()), len(net.ders)) == (n_bus, n_branch, in_service, n_der)
    assert net.load_p_mw.sum() == pytest.approx(load_p, abs=1e-6) and net.load_q_mvar.sum() == pytest.approx(load_q, abs=1e-6)
    assert net.meshed == meshed and np.isfinite(net.r).all() and np.isfinite(net.x).all()


def test_case141_power_factor_conversion():
    net = load_network("case141")
    nz = net.load_p_mw > 0
    pf = net.load_p_mw[nz] / np.hypot(net.load_p_mw[nz], net.load_q_mvar[nz])
    assert np.allclose(pf, 0.85)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda s: s.replace("mpc.bus = [", "mpc.bux = ["), r"unsupported matrix mpc\.bux"),
        (lambda s: s.split("mpc.bus = [")[0] + "mpc.gen" + s.split("mpc.gen", 1)[1], r"missing mpc\.bus"),
        (lambda s: s.replace("mpc.baseMVA = 10;", ""), r"missing mpc\.baseMVA"),
        (
            lambda s: s.replace(
                "\t3\t1\t90\t40\t0\t0\t1\t1\t0\t12.66\t1\t1.1\t0.9;", "\t3\t1\t90\t40\t0\t0\t1\t1\t0\t12.66\t1\t1.1;"
            ),
            r"mpc\.bus row 3 \(line 7\) has 12 columns, row 1 has 13",
        ),
        (lambda s: s.replace("\t2\t3\t0.4930", "\t2\t7\t0.4930"), r"mpc\.branch row 2: to bus 7 is not a bus"),
        (
            lambda s: s.replace("\t2\t1\t100\t60", "\t2\t1\tabc\t60"),
            r"mpc\.bus row 2 \(line 6\), column 3: non-numeric entry 'abc'",
        ),
        (lambda s: s + "mpc.bus(:, PD) = 2 * mpc.bus(:, PD);\n", r"line 28: unrecognized code line"),
        (lambda s: s.replace("\t0.2511\t0\t0\t0\t0\t0\t0\t1\t", "\t0.2511\t0\t0\t0\t0\t0\t0\t0\t"), r"islanded .*: 3"),
        (
            lambda s: s.replace("mpc.branch = [", "mpc.branch = [\n\t1\t2\t0.1\t0.1\t0\t0\t0\t0\t0\t0;"),
            r"mpc\.branch row 2 \(line \d+\) has 13 columns, row 1 has 10",
        ),
        (lambda s: s.replace("\t1\t3\t0\t0", "\t1\t1\t0\t0"), r"exactly one reference bus"),
        (lambda s: s.replace("mpc.version = '2';", "mpc.version = '1';"), r"version '2'"),
        (lambda s: s.replace("];\nmpc.gen", "\nmpc.gen", 1), r"non-numeric entry 'mpc.gen"),
    ],
    ids=[
        "unknown-matrix",
        "missing-bus",
        "missing-baseMVA",
        "wrong-column-count",
        "unknown-bus",
        "non-numeric",
        "unrecognized-code",
        "islanded-bus",
        "ragged-branch",
        "no-slack",
        "version",
        "unclosed",
    ],
)
def test_malformed_case_names_the_problem(tmp_path, mutate, message):
    path = _write(tmp_path, mutate(TINY_CASE))
    with pytest.raises(CaseFormatError, match=message) as info:
        load_case_file(path)
    assert str(path) in str(info.value)


def test_too_few_columns(tmp_path):
    text = TINY_CASE.replace("\t0\t0\t0\t0\t0\t0\t1\t-360\t360;", ";")  # branch rows keep fbus tbus r x
    with pytest.raises(CaseFormatError, match=r"mpc\.branch has 4 columns, MATPOWER v2 needs at least 11"):
        load_case_file(_write(tmp_path, text))


def test_missing_file_and_unknown_case(tmp_path):
    with pytest.raises(CaseFormatError, match="cannot read"):
        load_case_file(tmp_path / "nope.m")
    with pytest.raises(InputError, match="unknown case 'nope'"):
        load_network("nope")

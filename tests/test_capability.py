"""DER capability at every breakpoint (paper §III)."""

import numpy as np
import pytest

from opfbench.capability import PAPER_KS, check_reserve, dfig_qmax, p_for_q, pv_qmax, pv_qmax_night, q_peak, qmax
from opfbench.errors import InputError


@pytest.mark.parametrize(
    "p, expected",
    [
        (0.0, 0.0),  # no power, PF limit gives no Q
        (0.3, 0.225),  # PF-limited: 0.75·P
        (0.48, 0.36),  # the crossover at P = 0.8·S̄: 0.75·0.48 = √(0.36−0.2304) = 0.36
        (0.54, np.sqrt(0.36 - 0.54**2)),  # S-limited above 0.8 p.u.
        (0.6, 0.0),  # full output: no room left
    ],
)
def test_pv_limit(p, expected):
    assert pv_qmax(np.array(p), np.array(0.6)) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize(
    "pu, expected_pu",
    [(0.0, 1.0), (0.2, 1.0), (0.4, 1.0), (0.4 + 1e-9, 1.0), (0.7, -5 / 6 * 0.7 + 4 / 3), (0.8, 2 / 3), (1.0, 0.5)],
)
def test_dfig_curve(pu, expected_pu):
    assert dfig_qmax(np.array(pu * 0.6), np.array(0.6)) == pytest.approx(expected_pu * 0.6, abs=1e-8)


def test_dfig_at_rated_power_gives_half_and_paper_fault_trace():
    # the paper's fault trace at bus 27 shows 0.6 MVAr: DFIG rated 0.6 MW at p ≤ 0.4
    assert dfig_qmax(np.array(0.2), np.array(0.6)) == pytest.approx(0.6)
    assert dfig_qmax(np.array(0.6), np.array(0.6)) == pytest.approx(0.3)


def test_kinds_mix_in_one_call():
    full = qmax(("PV", "DFIG"), np.array([[0.48, 0.48]]), np.array([0.6, 0.6]))
    assert full.tolist() == [[pytest.approx(0.36), pytest.approx(0.4)]]


def test_reserve_is_one_number_in_the_unit_interval():
    assert PAPER_KS == (0.0, 0.2, 0.4, 0.6, 0.8)
    for k in (*PAPER_KS, 1.0, np.float32(0.5), 1):
        assert check_reserve(k) == float(k) and type(check_reserve(k)) is float
    with pytest.raises(InputError, match="k must be one number, got shape \\(2,\\)"):
        check_reserve(np.array([0.1, 0.2]))


def test_night_variant_is_s_limited_only():
    assert pv_qmax_night(np.array(0.0), np.array(0.6)) == pytest.approx(0.6)
    assert pv_qmax(np.array(0.0), np.array(0.6)) == 0.0


@pytest.mark.parametrize("k", [-0.1, 1.01, float("nan")])
def test_k_out_of_range(k):
    with pytest.raises(InputError, match=r"k must lie in \[0, 1\]"):
        check_reserve(k)


@pytest.mark.parametrize("p", [-0.01, 0.61, float("nan")])
def test_p_out_of_range(p):
    with pytest.raises(InputError, match="DER active power"):
        pv_qmax(np.array([p]), np.array([0.6]))


def test_unknown_kind():
    with pytest.raises(InputError, match="unknown DER kind"):
        qmax(("BESS",), np.array([0.1]), np.array([0.6]))


# ----- reactive priority: the peak a unit reaches by curtailing, and the power it keeps ------
KINDS3 = ("PV", "inverter", "DFIG")
RATING3 = np.array([0.6, 0.6, 0.6])
S3 = np.array([0.6, 0.6 / 0.9, 0.6])


@pytest.mark.parametrize(
    "share, expected",
    [(1.0, [0.36, 0.6 / 0.9 * np.sin(np.arccos(0.9)), 0.6]), (0.5, [0.36, 0.6 / 0.9 * np.sin(np.arccos(0.9)), 0.6])],
)
def test_q_peak_is_where_the_power_factor_line_meets_the_circle(share, expected):
    """PV peaks at P = 0.8·S̄ (0.36 MVAr of 0.6), the inverter at 0.9·S̄ (its rating: S̄ = P̄/0.9),
    the DFIG at P = 0 (its curve falls from there): at full output they reach it by curtailing."""
    full = np.broadcast_to(RATING3, (1, 3))
    assert q_peak(KINDS3, full, RATING3, S3)[0] == pytest.approx(expected, abs=1e-12)
    low = np.array([[0.1, 0.1, 0.1]])  # below the peak's power: nothing to gain by curtailing (but the DFIG)
    assert q_peak(KINDS3, low, RATING3, S3)[0, :2] == pytest.approx(qmax(KINDS3, low, RATING3, S3)[0, :2], abs=1e-15)


def test_p_for_q_keeps_the_most_power_that_still_covers_q():
    """For Q up to the peak: (1 − k)·Qmax at the kept power covers |Q| exactly where power is
    curtailed, and a hair more power would not; no curtailment where Qmax(P) already covers it;
    a unit drawing its own consumption keeps it."""
    rng = np.random.default_rng(7)
    for share in (1.0, 0.6):
        p = rng.uniform(0.0, 1.0, (200, 3)) * RATING3
        q = rng.uniform(-1.0, 1.0, (200, 3)) * share * q_peak(KINDS3, p, RATING3, S3)
        kept = p_for_q(KINDS3, q, p, RATING3, S3, share=share)
        cover = share * qmax(KINDS3, kept, RATING3, S3)
        assert (kept <= p + 1e-15).all() and (cover >= np.abs(q) - 1e-12).all()
        cut = kept < p - 1e-12
        assert cut.any() and np.allclose(cover[cut], np.abs(q[cut]), atol=1e-12)
        more = np.minimum(kept + 1e-6, p)
        assert (share * qmax(KINDS3, more, RATING3, S3)[cut] < np.abs(q[cut])).all()
    assert p_for_q(("inverter",), np.array([0.1]), np.array([-0.05]), np.array([0.6]), np.array([0.7]))[0] == -0.05
    assert p_for_q(KINDS3, np.zeros(3), RATING3, RATING3, S3).tolist() == RATING3.tolist()

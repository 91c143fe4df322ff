"""Case specs through `load_case`: shipped names, MATPOWER files (DER from generators or a
`der=` list), the no-DER note, the per-process and on-disk caches, bad specs."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from opfbench.cases import _matpower_file
from opfbench.cli import main
from opfbench.errors import CaseFormatError, InputError
from opfbench.io import NO_DER_NOTE, load_case, load_network, parse_spec
from opfbench.io.case import Case
from opfbench.io.disk_cache import cached_case

GEN_CASE = """function mpc = gens
mpc.version = '2';
mpc.baseMVA = 10;
mpc.bus = [
\t1\t3\t0\t0\t0\t0\t1\t1\t0\t12.66\t1\t1.1\t0.9;
\t2\t2\t1.0\t0.4\t0\t0\t1\t1\t0\t12.66\t1\t1.1\t0.9;
\t3\t1\t0.8\t0.3\t0\t0\t1\t1\t0\t12.66\t1\t1.1\t0.9;
];
mpc.gen = [
\t1\t0\t0\t10\t-10\t1.0\t100\t1\t10\t0;
\t2\t0.3\t0\t1\t-1\t1.01\t100\t1\t0.5\t0;
];
mpc.branch = [
\t1\t2\t0.01\t0.02\t0\t0\t0\t0\t0\t0\t1\t-360\t360;
\t2\t3\t0.02\t0.03\t0\t0\t0\t0\t0\t0\t1\t-360\t360;
];
"""


def test_shipped_names_and_the_no_der_note():
    assert load_case("paper33").network is load_network("paper33")
    assert NO_DER_NOTE not in load_case("paper33").notes
    assert NO_DER_NOTE in load_case("case33bw").notes and not load_case("case33bw").network.ders


def test_der_list_on_a_case_without_der():
    case = load_case("case33bw?der=10:PV:0.6,27:DFIG:0.6,18:inverter:0.3")
    net = case.network
    assert [d.kind for d in net.ders] == ["PV", "DFIG", "inverter"] and NO_DER_NOTE not in case.notes
    assert [int(net.bus_ids[d.bus]) for d in net.ders] == [10, 27, 18]
    assert net.der_s_mva.tolist() == pytest.approx([0.6, 0.6, 0.3 / 0.9])
    assert [d.primary_energy for d in net.ders] == ["solar", "wind", "solar"]
    assert load_case("case33bw?der=18:inverter:0.3&der-pf=0.95").network.der_s_mva[0] == pytest.approx(0.3 / 0.95)


def test_generators_as_der(tmp_path):
    path = tmp_path / "gens.m"
    path.write_text(GEN_CASE)
    plain = load_network(str(path))
    assert plain.gen_bus.tolist() == [1] and not plain.ders and plain.bus_type[1] == 2
    case = load_case(f"{path}?der=gens")
    net = case.network
    assert not net.gen_bus.size and net.bus_type[1] == 1  # the DER's bus is a PQ bus now
    (der,) = net.ders
    assert (der.kind, der.rating_mw, der.primary_energy) == ("inverter", 0.5, "solar")
    assert der.s_rated_mva == pytest.approx(0.5 / 0.9) and case.stored[2].tolist() == [0.3]
    assert np.array_equal(case.stored[0], net.load_p_mw[net.load_bus])


@pytest.mark.parametrize(
    "spec, message",
    [
        ("paper33?der=10:PV:0.5", "already has 5 DER"),
        ("case33bw?der=99:PV:0.5", "no such bus"),
        ("case33bw?der=10:BESS:0.5", "KIND must be one of"),
        ("case33bw?der=10:PV:-1", "MW must be a positive number"),
        ("case33bw?der=10:PV", "must be BUS:KIND:MW"),
        ("case33bw?der=10:inverter:0.1:geothermal", "ENERGY must be one of"),
        ("case33bw?der=gens", "der=gens reads a MATPOWER file's generators"),
        ("case33bw?der-pf=1.2", "der-pf must lie in"),
        ("case33bw?colour=red", "unknown option 'colour'"),
        ("case33bw?line-z=1.1&line-z=1.2", "option line-z given twice"),
        ("case33bw?der=18:PV:0.5&der=25:PV:0.5", "option der given twice"),
        ("case33bw?der=18:inverter:0.5&der-pf=0.9&der-pf=0.95", "option der-pf given twice"),
        ("case33bw?der=18:inverter:0.5&der-pf=nan", "der-pf must be a number in"),
        ("nope", "unknown case 'nope'"),
        ("missing.m", "not found"),
    ],
)
def test_bad_specs_are_one_message(spec, message, capsys):
    with pytest.raises(InputError, match=message):
        load_case(spec)
    assert main(["pf", spec]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_generator_without_rating_is_refused(tmp_path):
    path = tmp_path / "zero.m"
    path.write_text(GEN_CASE.replace("\t2\t0.3\t0\t1\t-1\t1.01\t100\t1\t0.5\t0;", "\t2\t0\t0\t1\t-1\t1.01\t100\t1\t0\t0;"))
    with pytest.raises(CaseFormatError, match="mpc.gen row 2: PMAX 0 and PG 0 MW give no positive DER rating"):
        load_case(f"{path}?der=gens")


def test_cli_der_option_reaches_the_spec(capsys):
    assert main(["pf", "case33bw", "--der", "18:inverter:0.3", "--der-pf", "0.95", "--json"]) == 0
    out = capsys.readouterr().out
    assert '"spec": "case33bw?der=18:inverter:0.3&der-pf=0.95"' in out and '"der_mw": 0.24' in out


def test_spec_text_is_canonical():
    assert parse_spec("x.m?der-pf=0.9&der=gens").text == "x.m?der=gens&der-pf=0.9"


def test_option_values_are_kept_exactly_not_rounded(capsys):
    spec = "case33bw?der=18:inverter:0.3&der-pf=0.91234567"
    assert parse_spec(spec).text == spec and parse_spec("paper33?line-z=1.0000001").text == "paper33?line-z=1.0000001"
    assert load_case(spec).network.der_s_mva[0] == 0.3 / 0.91234567  # the model is the value given, not 0.912346's
    assert main(["pf", "case33bw", "--der", "18:inverter:0.3", "--der-pf", "0.91234567", "--json"]) == 0
    assert f'"spec": "{spec}"' in capsys.readouterr().out
    # given twice — in the spec and as a flag — is refused, naming it
    assert main(["pf", "case33bw?der=18:inverter:0.3&der-pf=0.9", "--der-pf", "0.95"]) == 2
    assert "option der-pf given twice" in capsys.readouterr().err


def test_disk_cache_round_trip(tmp_path, monkeypatch):
    monkeypatch.setenv("OPFBENCH_CACHE", str(tmp_path))
    built = []

    def build() -> Case:
        built.append(1)
        return load_case("case33bw?der=10:PV:0.6")

    first = cached_case("unit-test", build)
    again = cached_case("unit-test", build)
    assert len(built) == 1 and again is not first
    assert np.array_equal(again.network.r, first.network.r) and again.network.ders == first.network.ders
    with pytest.raises(ValueError, match="read-only"):
        again.network.r[0] = 0  # rebuilt through the constructor: read-only again
    (entry,) = tmp_path.glob("unit-test-*.pickle")
    entry.write_bytes(b"not a pickle")
    cached_case("unit-test", build)  # a damaged entry is rebuilt, not trusted
    assert len(built) == 2 and pickle.loads(entry.read_bytes())["spec"] == first.spec
    monkeypatch.setenv("OPFBENCH_CACHE", "off")
    cached_case("unit-test", build)
    assert len(built) == 3


def test_cases_command_lists_loads_and_series(capsys):
    assert main(["cases", "case33bw", str(_matpower_file("case69"))]) == 0
    out = capsys.readouterr().out
    assert "case33bw" in out and "loads" in out and "series" in out


def test_every_help_and_error_text_names_the_formats_as_the_sources_declare_them(capsys):
    """The formats a case spec accepts are listed once (`opfbench.io.sources`): the commands'
    help, `opfbench cases` and the errors of a bad spec all say `formats()`."""
    from opfbench.cli import main
    from opfbench.io.sources import SOURCES, formats

    def squeezed(text: str) -> str:
        return "".join(text.split())

    assert {s.kind for s in SOURCES} >= {"shipped", "matpower", "pandapower", "simbench"}
    for command in ("run", "pf", "snapshot", "fault", "table"):
        assert main([command, "--help"]) == 0
        assert squeezed(formats()) in squeezed(capsys.readouterr().out), command
    assert main(["cases"]) == 0 and squeezed(formats(without="shipped")) in squeezed(capsys.readouterr().out)
    for spec, expected in (("nope", formats(without="shipped")), ("missing.m", formats()), ("", formats())):
        with pytest.raises(InputError) as raised:
            load_network(spec)
        assert expected in str(raised.value), spec

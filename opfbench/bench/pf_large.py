"""Large-feeder figures of the power-flow benchmark (`python -m opfbench.bench pf --large`).

On `feeder10k` (9 999 buses, 1 515 DER; rule in `opfbench.cases.feeder`), each
measurement runs in a fresh `spawn` process, so its peak memory is its own:

- `large_pf_s`: one Newton–Raphson power flow (DER at 0.8·rating, Q = 0), best of 5
  warm calls; `large_pf_first_s` the first call, with the one-time Jacobian set-up;
- `large_batch96_s`: the batched solver on 96 snapshots (the paper day every 15 min,
  DER Q = 0), best of 3; `large_batch96_first_s` the first call, with the factorization;
- `large_acopf_s`: `run_strategy("acopf")` (AC OPF + SOCP bound + AC evaluation, as the
  registry runs it) on the noon snapshot, k = 0, one call;
- `large_lfma96_s`: `run_strategy("lfma")` on the 96 snapshots, k = 0.4, one call.

`*_mb` is the peak resident set of the process during the measured calls (Linux
VmHWM, reset just before them through /proc/self/clear_refs; without that, the
lifetime `ru_maxrss`) — the interpreter, libraries and the 10 000-bus case that were
already resident included, so an upper bound on what the calls themselves need;
`*_baseline_mb` the resident set just before them. `*_cpu_s` is the CPU time of the
timed call(s) divided by their number: on a busy machine wall time inflates, CPU time
much less. Each process runs under an address-space cap (`CAP_GIB`) and a time limit,
so a solver that would exhaust the machine fails alone: its figures are then null and
`*_error` says why.

`large_scaling` times the same three local computations (single PF, batch of 96, LFMA
on 96) on paper33, case141-der, feeder1k and feeder10k in this process, and
`large_exponents` fits t ∝ n_bus^e to them by least squares on logs.
"""

from __future__ import annotations

import multiprocessing as mp
import resource
import time
import traceback

import numpy as np

from opfbench.timing import best_ms, elapsed_ms, now

LARGE_CASE = "feeder10k"
SCALING_CASES = ("paper33", "case141-der", "feeder1k", "feeder10k")
SNAPSHOTS = 96  # the paper day every 15 minutes
CAP_GIB = {"pf": 4, "batch96": 4, "acopf": 8, "lfma96": 6}
TIME_LIMIT_S = {"pf": 300, "batch96": 300, "acopf": 900, "lfma96": 600}


def day96(case: str):
    """The paper day on `case` at 15-minute steps (96 snapshots)."""
    from opfbench.bench.paper_day import paper_day_scenario

    return paper_day_scenario(case).take(slice(0, 1440, 1440 // SNAPSHOTS))


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * resource.getpagesize() / 2**20


def _job(task: str, case: str):
    """(timed callable, repeats) of one measurement, its inputs built outside the timing."""
    from opfbench.powerflow import bus_injections, solve_pf, solve_pf_batch
    from opfbench.powerflow.memo import cold
    from opfbench.registry.catalog import run_strategy

    day = day96(case)
    net = day.net
    if task == "pf":
        s = bus_injections(net, 0.8 * net.der_rating_mw)
        return (lambda: solve_pf(net, s)), 5
    if task == "batch96":
        s = day.injections(np.zeros_like(day.der_p_mw))
        return (lambda: cold(solve_pf_batch, net, s)), 3
    if task == "acopf":
        noon = int(np.argmax(day.der_p_mw.sum(axis=1)))
        one = day.take(slice(noon, noon + 1))
        return (lambda: cold(run_strategy, "acopf", one, 0.0)), 1
    if task == "lfma96":
        return (lambda: cold(run_strategy, "lfma", day, 0.4)), 1
    raise ValueError(task)


def _status_kb(field: str) -> int:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise OSError(f"no {field} in /proc/self/status")


def _reset_peak() -> bool:
    """Reset the peak resident set (VmHWM) to the current one; False where Linux does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _worker(task: str, case: str, cap_gib: float, conn) -> None:
    try:
        cap = int(cap_gib * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        fn, repeats = _job(task, case)
        baseline = _rss_mb()
        reset = _reset_peak()
        cpu, start = time.process_time(), now()
        out = fn()
        first = elapsed_ms(start) / 1e3
        best = min(first, best_ms(fn, repeats - 1)[0] / 1e3) if repeats > 1 else first
        cpu = (time.process_time() - cpu) / repeats
        peak = _status_kb("VmHWM") / 1024 if reset else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        conn.send(
            {"first_s": first, "s": best, "cpu_s": cpu, "baseline_mb": baseline, "mb": peak, "ok": _succeeded(out), "error": None}
        )
    except BaseException as exc:  # noqa: BLE001 — reported to the parent, never swallowed
        conn.send({"error": f"{type(exc).__name__}: {exc}"[:300], "trace": traceback.format_exc()[-2000:]})
    finally:
        conn.close()


def _succeeded(out) -> bool:
    """True when a power flow converged everywhere / a strategy returned finite losses."""
    if hasattr(out, "converged"):
        return bool(np.all(out.converged))
    return bool(np.all(np.isfinite(out.losses_kw)))


def measure(task: str, case: str = LARGE_CASE) -> dict:
    """Run one measurement in a fresh spawn process; its figures or an error."""
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_worker, args=(task, case, CAP_GIB[task], send), daemon=True)
    proc.start()
    send.close()
    result = {"error": f"no answer within {TIME_LIMIT_S[task]} s"}
    if recv.poll(TIME_LIMIT_S[task]):
        try:
            result = recv.recv()
        except EOFError:
            result = {"error": "the measuring process died without an answer"}
    proc.join(5)
    if proc.is_alive():
        proc.kill()
        proc.join()
    if result.get("error") is None and proc.exitcode not in (0, None):
        result["error"] = f"exit code {proc.exitcode}"
    return result


def _scaling_row(case: str) -> dict:
    """Best-of seconds of single PF, batch of 96 and LFMA on 96 on `case`, set-up excluded."""
    from opfbench.powerflow import bus_injections, solve_pf, solve_pf_batch
    from opfbench.powerflow.memo import cold
    from opfbench.registry.catalog import run_strategy

    day = day96(case)
    net = day.net
    s_one = bus_injections(net, 0.8 * net.der_rating_mw)
    s_day = day.injections(np.zeros_like(day.der_p_mw))
    solve_pf_batch(net, s_day)  # one-time set-up (factors, Jacobian pattern) outside the timing
    solve_pf(net, s_one)
    reps = 1 if net.n_bus > 5000 else 3
    return {
        "buses": net.n_bus,
        "pf_s": best_ms(lambda: solve_pf(net, s_one), 3 * reps)[0] / 1e3,
        "batch96_s": best_ms(lambda: cold(solve_pf_batch, net, s_day), reps)[0] / 1e3,
        "lfma96_s": best_ms(lambda: run_strategy("lfma", day, 0.4), reps)[0] / 1e3,
    }


def scaling(cases=SCALING_CASES) -> tuple[dict, dict]:
    """(per-case seconds of single PF, batch of 96 and LFMA on 96, fitted exponents e of
    t ∝ n_bus^e, least squares on logs)."""
    rows = {case: _scaling_row(case) for case in cases}
    n = np.log([r["buses"] for r in rows.values()])
    exponents = {
        key: float(np.polyfit(n, np.log([r[key] for r in rows.values()]), 1)[0]) for key in ("pf_s", "batch96_s", "lfma96_s")
    }
    return rows, exponents


def run_large() -> dict:
    """Every large-feeder figure (see the module docstring)."""
    import os

    out: dict = {"large_case": LARGE_CASE, "load_average_before": os.getloadavg()[0]}
    for task in ("pf", "batch96", "acopf", "lfma96"):
        r = measure(task)
        out[f"large_{task}_s"] = r.get("s")
        out[f"large_{task}_mb"] = r.get("mb")
        out[f"large_{task}_baseline_mb"] = r.get("baseline_mb")
        out[f"large_{task}_cpu_s"] = r.get("cpu_s")
        if task in ("pf", "batch96"):
            out[f"large_{task}_first_s"] = r.get("first_s")
        out[f"large_{task}_ok"] = r.get("ok")
        out[f"large_{task}_error"] = r.get("error")
    out["large_scaling"], out["large_exponents"] = scaling()
    out["load_average_after"] = os.getloadavg()[0]
    return out


def print_large(f: dict) -> None:
    print(f"large feeder {f['large_case']} (each figure in a fresh process; peak RSS includes interpreter and case)")
    labels = {
        "pf": "one power flow (NR)",
        "batch96": "batched, 96 snapshots",
        "acopf": "AC OPF, one snapshot",
        "lfma96": "LFMA, 96 snapshots",
    }
    for task, label in labels.items():
        if f[f"large_{task}_error"]:
            print(f"  {label:<24} FAILED: {f[f'large_{task}_error']}")
        else:
            print(
                f"  {label:<24} {f[f'large_{task}_s']:8.3f} s (CPU {f[f'large_{task}_cpu_s']:.3f} s)  peak {f[f'large_{task}_mb']:7.0f} MB "
                f"(before the call {f[f'large_{task}_baseline_mb']:.0f} MB){'' if f[f'large_{task}_ok'] else '  NOT OK'}"
            )
    print("  time vs buses (s):")
    for case, r in f["large_scaling"].items():
        print(
            f"    {case:<12} {r['buses']:>6} buses  PF {r['pf_s']:.4f}  batch96 {r['batch96_s']:.4f}  LFMA96 {r['lfma96_s']:.4f}"
        )
    e = f["large_exponents"]
    print(f"  fitted exponents (t ∝ n^e): PF {e['pf_s']:.2f}, batch96 {e['batch96_s']:.2f}, LFMA96 {e['lfma96_s']:.2f}")
    print(f"  load average before/after: {f['load_average_before']:.1f} / {f['load_average_after']:.1f}")

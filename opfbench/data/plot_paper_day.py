"""Plot the paper day's load, PV and wind profiles to a PNG.

python -m opfbench.data.plot_paper_day docs/paper_day.png
"""

from __future__ import annotations

import sys
from pathlib import Path

from opfbench.data.night import night_mask
from opfbench.data.profiles import PAPER_DAY, PAPER_DAY_TZ, paper_day


def plot_paper_day(path: Path) -> None:
    """Write a PNG of `paper_day` (p.u. multipliers over local time; night shaded)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt

    day = paper_day()
    hours = day.index.tz_localize(None)
    fig, ax = plt.subplots(figsize=(9, 4), dpi=100)
    ax.fill_between(hours, 0, 1.05, where=night_mask(day.index).to_numpy(), color="0.9", label="night (sun below horizon)")
    ax.plot(hours, day["load"], label=f"load ({day.attrs['load_profile'].split(':')[-1]}, day peak = 1)", color="C3")
    ax.plot(hours, day["pv"], label="PV (BSRN Payerne, 10 kW plant, 1 min)", color="C1", lw=0.8)
    ax.plot(hours, day["wind"], label=f"wind ({day.attrs['wind_profile'].split(':')[-1]}, 15 min → 1 min)", color="C0")
    ax.set_xlim(hours[0], hours[-1])
    ax.set_ylim(0, 1.05)
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%H:%M"))
    ax.set_xlabel(f"local time ({PAPER_DAY_TZ}), {PAPER_DAY}")
    ax.set_ylabel("per unit")
    ax.set_title("Paper day: per-unit profiles")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, metadata={"Software": None})
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m opfbench.data.plot_paper_day OUTPUT.png", file=sys.stderr)
        return 2
    plot_paper_day(Path(args[0]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""How the chosen values of configs/best.toml are selected, reproducibly (README "Fast motion").

Each candidate (best.toml with one combination of CANDIDATES) runs twice on the selection
data: the real excerpt's first 20 s (`histeq`, time offset 0.01 s) and `synthetic:default`
(`eas`). The rule, fixed before running: keep the candidates at least 10x real time on both
(the better of the two runs), take the lowest geometric-mean APE, and among those within 2 % of
it the fastest (the higher of its two slower real-time factors). Prints every candidate and
the choice; held-out data (real 20-30 s, fresh simulator seeds) is for reporting, never here.

    python benchmarks/select_best.py [--real ../shared/data/ecd/shapes_rotation_0-30s]
"""

from __future__ import annotations

import argparse
import itertools
import math
from pathlib import Path

from eas_vo import config, pipeline

#: The values tried (every other value is best.toml's).
CANDIDATES = {
    "tracker.max_corners": (500, 1000),
    "tracker.lk_win_size": (15, 21),
    "tracker.threshold2": (150, 300),
    "tracker.loop_every": (5, 10),
    "tracker.loop_keyframe_deg": (5.0, 10.0),
}
REAL_TIME_BAR = 10.0
WITHIN = 0.02


def measure(dataset: str, frontend: str, extra: dict, assignments: list[str], runs: int = 2) -> tuple[float, float]:
    """(average APE [rad], best real-time factor of `runs`)."""
    cfg = config.resolve("best", {"dataset": dataset, "frontend": frontend, **extra}, assignments)
    results = [pipeline.run(cfg).metrics for _ in range(runs)]
    return results[0]["ape_mean_rad"], max(m["realtime_factor"] for m in results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real", default="../shared/data/ecd/shapes_rotation_0-30s", help="the real excerpt's folder")
    args = parser.parse_args()
    if not Path(args.real).is_dir():
        raise SystemExit(f"{args.real}: the real excerpt is needed (see ../shared/data/README.md)")
    rows = []
    for values in itertools.product(*CANDIDATES.values()):
        assignments = [f"{k}={v}" for k, v in zip(CANDIDATES, values)]
        ape_real, rtf_real = measure(args.real, "histeq", {"duration_s": 20.0, "time_offset_s": 0.01}, assignments)
        ape_syn, rtf_syn = measure("synthetic:default", "eas", {}, assignments)
        rows.append({"values": values, "ape": (ape_real, ape_syn), "rtf": (rtf_real, rtf_syn),
                     "geomean": math.sqrt(ape_real * ape_syn), "fast": min(rtf_real, rtf_syn) >= REAL_TIME_BAR})
        r = rows[-1]
        print(" ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(CANDIDATES, values)),
              f"APE {ape_real:.4f} / {ape_syn:.4f} (geomean {r['geomean']:.4f}), real time x{rtf_real:.1f} / x{rtf_syn:.1f}",
              "" if r["fast"] else "(too slow)", flush=True)
    fast = [r for r in rows if r["fast"]]
    if not fast:
        print(f"no candidate is {REAL_TIME_BAR:g}x real time on both: nothing chosen")
        return
    best = min(r["geomean"] for r in fast)
    chosen = max((r for r in fast if r["geomean"] <= best * (1 + WITHIN)), key=lambda r: min(r["rtf"]))
    print(f"{len(fast)} of {len(rows)} pass the speed bar; lowest geometric mean {best:.4f}; chosen:",
          " ".join(f"{k}={v}" for k, v in zip(CANDIDATES, chosen["values"])))


if __name__ == "__main__":
    main()

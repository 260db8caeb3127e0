#!/usr/bin/env python3
"""Check a run's ATE against evo's (pip install evo).

Usage: scripts/compare_evo.py RUN_DIR

Loads RUN_DIR/groundtruth.txt and RUN_DIR/trajectory.txt with evo, aligns
them with Umeyama SE(3) (no scale, as `evo_ape tum GT EST -a`), and prints
evo's RMSE and mean next to ours from RUN_DIR/metrics.json, with their ratio.
Exit status 1 if they differ by more than 1 %.
"""
import json
import sys
from pathlib import Path

from evo.core import metrics, sync
from evo.tools import file_interface


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    run = Path(sys.argv[1])
    gt = file_interface.read_tum_trajectory_file(str(run / "groundtruth.txt"))
    est = file_interface.read_tum_trajectory_file(str(run / "trajectory.txt"))
    gt, est = sync.associate_trajectories(gt, est, max_diff=0.005)
    est.align(gt, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((gt, est))
    stats = ape.get_all_statistics()
    ours = json.loads((run / "metrics.json").read_text())
    ok = True
    for name, key in (("rmse", "ate_rmse_cm"), ("mean", "ate_mean_cm")):
        evo_cm = stats[name] * 100.0
        our_cm = ours[key]
        ratio = our_cm / evo_cm if evo_cm > 0 else float("nan")
        ok &= abs(ratio - 1.0) <= 0.01
        print(f"{name:5s}  evo {evo_cm:.6f} cm   opengs {our_cm:.6f} cm   ratio {ratio:.5f}")
    print(f"{len(est.timestamps)} poses compared: {'agree within 1 %' if ok else 'DISAGREE'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

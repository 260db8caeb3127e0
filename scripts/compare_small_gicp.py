#!/usr/bin/env python3
"""Time small_gicp on the clouds written by `opengs bench gicp --dump DIR`.

Same clouds, k, max correspondence distance, iteration limit and
convergence thresholds as our bench; small_gicp's own covariances (plane
regularisation, compare with our `[plane]` lines) and its default solver
(Levenberg-Marquardt). Prints the median registration time per thread count
and, given `--ours-ms`, the ratio ours / small_gicp.

    pip install small_gicp numpy
    opengs bench gicp --plane --dump /tmp/gicp_bench
    python3 scripts/compare_small_gicp.py /tmp/gicp_bench --ours-ms 1=12.3,2=7.1

On a loaded machine compare the CPU figures (process CPU time per
registration; for one thread that is the work itself, not the waiting).
"""
import argparse
import pathlib
import statistics
import sys
import time

import numpy as np
import small_gicp


def read_settings(path):
    settings = {}
    for line in path.read_text().splitlines():
        key, _, value = line.partition(" ")
        settings[key] = value
    return settings


def matrix(text):
    values = [float(v) for v in text.split()]
    if len(values) != 16:
        sys.exit(f"expected 16 numbers, got {len(values)}")
    return np.array(values).reshape(4, 4)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("dir", type=pathlib.Path)
    parser.add_argument("--repeats", type=int, default=21)
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--ours-ms", default="", help="our medians, e.g. 1=12.3,2=7.1")
    args = parser.parse_args()

    settings = read_settings(args.dir / "settings.txt")
    source_points = np.loadtxt(args.dir / "source.xyz", comments="#")
    target_points = np.loadtxt(args.dir / "target.xyz", comments="#")
    k = int(settings["neighbours"])
    max_corr = float(settings["max_correspondence_distance"])
    max_iterations = int(settings["max_iterations"])
    rot_eps = float(settings["rotation_epsilon"])
    trans_eps = float(settings["translation_epsilon"])
    init = matrix(settings["init"])
    truth = matrix(settings["truth"])
    ours = dict(kv.split("=") for kv in args.ours_ms.split(",") if kv)
    print(f"source {len(source_points)} points, target {len(target_points)} points, k={k}, max_corr={max_corr}")

    target = small_gicp.PointCloud(target_points)
    target_tree = small_gicp.KdTree(target, num_threads=2)
    small_gicp.estimate_covariances(target, target_tree, num_neighbors=k, num_threads=2)

    for threads in [int(t) for t in args.threads.split(",")]:
        cov_ms, reg_ms = [], []
        for _ in range(args.repeats):
            start = time.perf_counter()
            source = small_gicp.PointCloud(source_points)
            source_tree = small_gicp.KdTree(source, num_threads=threads)
            small_gicp.estimate_covariances(source, source_tree, num_neighbors=k, num_threads=threads)
            cov_ms.append((time.perf_counter() - start) * 1e3)
        cpu_start = time.process_time()
        for _ in range(args.repeats):
            start = time.perf_counter()
            result = small_gicp.align(
                target, source, target_tree, init,
                registration_type="GICP",
                max_correspondence_distance=max_corr,
                num_threads=threads,
                max_iterations=max_iterations,
                rotation_epsilon=rot_eps,
                translation_epsilon=trans_eps,
            )
            reg_ms.append((time.perf_counter() - start) * 1e3)
        cpu_ms = (time.process_time() - cpu_start) * 1e3 / args.repeats
        error_mm = np.linalg.norm(result.T_target_source[:3, 3] - truth[:3, 3]) * 1e3
        median = statistics.median(reg_ms)
        line = (f"small_gicp {threads} thread(s): registration median {median:.2f} ms wall, {cpu_ms:.2f} ms CPU "
                f"({result.iterations} iterations, {result.num_inliers} inliers), "
                f"source covariances {statistics.median(cov_ms):.2f} ms, error {error_mm:.2f} mm")
        if str(threads) in ours:
            mine = float(ours[str(threads)])
            line += f"; ours {mine:.2f} ms, ratio ours/small_gicp (wall) {mine / median:.2f}"
        print(line)


if __name__ == "__main__":
    main()

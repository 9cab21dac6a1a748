"""Closed-loop cost against the plant alone, fmpy's own master, CSV writing and the grid.

    python bench/bench_closed_loop.py            # one 50 s trial, measured side by side
    python bench/bench_closed_loop.py --grid     # plus the full 96-trial grid (2 workers)

Prints a table and writes bench/results/closed_loop.json. All numbers are wall times of
runs made here, on the reference plant (friction 3, resolution 3, perturbation 3, joint 1);
each is the median of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.signal import csd, welch

from orchestrator import Setup, get_plant, run_grid, simulate_trial
from orchestrator.trial import default_fmu_path, simulate_plant
from trialformat import reference, write_trial

from benchio import write_results

RESULTS = Path(__file__).resolve().parent / "results" / "closed_loop.json"
TARGET_RATIO, TARGET_GRID_S = 1.3, 120.0


def timed(fn, repeat, cpu=None):
    """Median wall time [s] of ``repeat`` calls and the last result; with ``cpu`` (a dict)
    also the median process CPU time, less sensitive to other work on a shared machine."""
    walls, cpus, out = [], [], None
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - start_cpu)
    if cpu is not None:
        cpu["s"] = statistics.median(cpus)
    return statistics.median(walls), out


def fmpy_zoh_input(tau_m, ts):
    """fmpy input table that holds tau_m[n] over [n Ts, (n+1) Ts).

    fmpy interpolates inputs linearly and sets them at each communication point. Rows
    ``(n Ts, u_n)`` and ``((n+1) Ts - eps, u_n)`` make the value at every communication
    point exactly u_n, held by the FMU over the step. (Repeated time points also give a
    ZOH, as events, but fmpy then searches its event list linearly at every step: O(N^2),
    185 s for one 50 s trial here.)
    """
    n, k = tau_m.shape
    rows = np.zeros(2 * n, dtype=[("time", float)] + [(f"tau_m[{j + 1}]", float)
                                                      for j in range(k)])
    rows["time"][0::2] = np.arange(n) * ts
    rows["time"][1::2] = (np.arange(n) + 1) * ts - 1e-6 * ts
    for j in range(k):
        rows[f"tau_m[{j + 1}]"][0::2] = tau_m[:, j]
        rows[f"tau_m[{j + 1}]"][1::2] = tau_m[:, j]
    return rows


def run_fmpy(fmu_path, setup, tau_m):
    from fmpy import simulate_fmu

    ts = setup.Ts
    return simulate_fmu(str(fmu_path), validate=False, start_time=0.0,
                        stop_time=tau_m.shape[0] * ts, output_interval=ts,
                        start_values=setup.plant_parameters(),
                        input=fmpy_zoh_input(tau_m, ts),
                        output=["theta[1]", "theta[2]", "tau_h[1]", "tau_h[2]"])


def tde_table(plant):
    """R_kk at friction 3 against 1/(Z_rd + Z_h,kk) with and without TDE (50 s trials,
    Table IV Welch), and the decomposition estimate's VAF of Z against Table I."""
    ctl = reference.controller()
    m_h, b_h, k_h = reference.arm_matrices()
    rows = {}
    for tde in (True, False):
        setup = Setup.reference(3, 0).with_controller(time_delay_estimation=tde)
        trials = [simulate_trial(setup, perturbed_dof=k, level=3, seed=30 + k, plant=plant,
                                 name=f"dof{k}") for k in (1, 2)]
        row = {}
        for k, trial in zip((1, 2), trials):
            j = k - 1
            x = trial.tau_delta[:, j]
            f, gxy = csd(x, trial.theta[:, j], fs=1000.0, nperseg=8192, noverlap=6144)
            _, gxx = welch(x, fs=1000.0, nperseg=8192, noverlap=6144)
            sel = (f > 0) & (f <= 15)
            w = 2 * np.pi * f[sel]
            z = (ctl["K_rd"][j] + k_h[j, j] - (ctl["M_rd"][j] + m_h[j, j]) * w**2
                 + 1j * (ctl["B_rd"][j] + b_h[j, j]) * w)
            r_true, r_hat = 1 / z, (gxy / gxx)[sel]
            row[f"R{k}{k}_vaf_pct"] = float(100 * (1 - np.sum(np.abs(r_hat - r_true) ** 2)
                                                   / np.sum(np.abs(r_true) ** 2)))
            row[f"R{k}{k}_median_rel_err"] = float(np.median(np.abs(r_hat - r_true)
                                                             / np.abs(r_true)))
        try:
            from estimation import estimate_impedance
            from estimation.accuracy import true_impedance, vaf
            est = estimate_impedance(trials)
            sel = (est.f > 0) & (est.f <= 15)
            row["Z_vaf_pct"] = vaf(est.Z[sel], true_impedance(est.f[sel], m_h, b_h,
                                                               k_h)).round(3).tolist()
        except ImportError:
            pass
        rows["tde_on" if tde else "tde_off"] = row
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", action="store_true", help="also run the 96-trial grid")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore")

    fmu = default_fmu_path()
    plant = get_plant(fmu)
    setup = Setup.reference(3, 3)
    simulate_trial(setup, perturbed_dof=1, duration_s=1.0, plant=plant)  # warm up
    res = {"machine_cpus": os.cpu_count(), "load_avg_1min": os.getloadavg()[0],
           "repeat": args.repeat}

    cpu_loop, cpu_plant = {}, {}
    t_loop, trial = timed(lambda: simulate_trial(setup, perturbed_dof=1, level=3, seed=0,
                                                 plant=plant), args.repeat, cpu_loop)
    t_plant, alone = timed(lambda: simulate_plant(setup, trial.tau_m, plant=plant),
                           args.repeat, cpu_plant)
    # the sampled theta is the quantised plant output: check the plant-alone replay
    res["plant_alone_vs_trial_max_theta_diff_rad"] = float(np.abs(alone["theta"]
                                                                  - trial.theta).max())
    t_fmpy, fm = timed(lambda: run_fmpy(fmu, setup, trial.tau_m), 1)
    fm_theta = np.column_stack([fm["theta[1]"], fm["theta[2]"]])[:trial.n_samples]
    res["fmpy_vs_plant_alone_max_theta_diff_rad"] = float(np.abs(fm_theta
                                                                 - alone["theta"]).max())
    with tempfile.TemporaryDirectory() as tmp:
        t_write, _ = timed(lambda: write_trial(Path(tmp) / "trial", trial), args.repeat)
        csv_mb = (Path(tmp) / "trial.csv").stat().st_size / 1e6

    res.update(closed_loop_trial_s=t_loop, plant_alone_s=t_plant,
               ratio_closed_loop_to_plant_alone=t_loop / t_plant,
               closed_loop_cpu_s=cpu_loop["s"], plant_alone_cpu_s=cpu_plant["s"],
               ratio_cpu=cpu_loop["s"] / cpu_plant["s"],
               controller_overhead_us_per_sample=(t_loop - t_plant) / trial.n_samples * 1e6,
               fmpy_simulate_fmu_s=t_fmpy, write_trial_s=t_write, trial_csv_mb=csv_mb,
               target_ratio=TARGET_RATIO)
    res["tde_friction3"] = tde_table(plant)
    if args.grid:
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            manifest = run_grid(tmp, workers=args.workers, fmu_path=fmu)
            res.update(grid_s=time.perf_counter() - start, grid_workers=args.workers,
                       grid_done=manifest["n_done"], grid_failed=manifest["n_failed"],
                       target_grid_s=TARGET_GRID_S)
    print_table(res)
    write_results(RESULTS.stem, res, indent=2)


def print_table(r):
    print(f"\n50 s trial, friction 3 / resolution 3 / perturbation 3, joint 1 "
          f"(median of {r['repeat']}; {r['machine_cpus']} CPUs, load {r['load_avg_1min']:.2f})")
    rows = [("closed loop (IMBIC master)", r["closed_loop_trial_s"]),
            ("plant alone (same master, recorded tau_m)", r["plant_alone_s"]),
            ("fmpy simulate_fmu (same plant, ZOH input)", r["fmpy_simulate_fmu_s"]),
            ("write_trial (CSV %.1f MB + JSON)" % r["trial_csv_mb"], r["write_trial_s"])]
    if "grid_s" in r:
        rows.append((f"full grid, 96 x 50 s, {r['grid_workers']} workers "
                     f"({r['grid_done']} done, {r['grid_failed']} failed)", r["grid_s"]))
    for name, value in rows:
        print(f"  {name:<58s} {value:8.2f} s")
    ok = "met" if r["ratio_closed_loop_to_plant_alone"] <= r["target_ratio"] else "MISSED"
    print(f"  closed loop / plant alone = {r['ratio_closed_loop_to_plant_alone']:.3f} "
          f"(target <= {r['target_ratio']}: {ok}); controller + sampler overhead "
          f"{r['controller_overhead_us_per_sample']:.2f} us/sample")
    print(f"  process CPU time: closed loop {r['closed_loop_cpu_s']:.2f} s, plant alone "
          f"{r['plant_alone_cpu_s']:.2f} s, ratio {r['ratio_cpu']:.3f}")
    if "grid_s" in r:
        ok = "met" if r["grid_s"] <= r["target_grid_s"] else "MISSED"
        print(f"  grid {r['grid_s']:.1f} s (target <= {r['target_grid_s']:.0f} s: {ok})")
    print(f"  fmpy vs plant alone: max |theta diff| "
          f"{r['fmpy_vs_plant_alone_max_theta_diff_rad']:.3g} rad")
    print("\nfriction 3, 50 s trials: R_kk vs 1/(Z_rd + Z_h,kk) and Z vs Table I")
    for key, row in r["tde_friction3"].items():
        z = f"  Z VAF {row['Z_vaf_pct']}" if "Z_vaf_pct" in row else ""
        print(f"  {key:<8s} R11 VAF {row['R11_vaf_pct']:7.3f} % (median rel err "
              f"{row['R11_median_rel_err']:.4f}), R22 VAF {row['R22_vaf_pct']:7.3f} % "
              f"(median {row['R22_median_rel_err']:.4f}){z}")


if __name__ == "__main__":
    main()

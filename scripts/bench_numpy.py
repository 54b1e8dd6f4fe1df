#!/usr/bin/env python3
"""grin against what a user would write instead: a vectorised numpy RK4.

The field is the expression GRIN rod n = 1.6 - 0.05 (x^2 + y^2) in a 10-unit box (field
kind `expr`), the rays a table of near-axial rays entering its z = 0 face. numpy integrates
the ray equation in t-form (dr/dt = T, dT/dt = n grad n) with fixed RK4 steps over all rays
at once (one array operation per stage for the whole table, one core), finishes each ray
on the exit face with Newton-corrected partial steps and refracts it out; grin traces the
same table with `grin trace`. Both are scored against a numpy RK4 at a step 64x finer
(the exit direction in radians), and each side's time to reach the asked error (1e-6 and
1e-9 by default) is read off its own error-versus-time curve, so the comparison is at equal
error whatever step each side needs.

    python3 scripts/bench_numpy.py [--grin target/release/grin] [--rays 100000] [--repeat 3] [--json]

100,000 rays by default: numpy's array operations then run on 1e5 rays at a time, as a user
tracing a table would; smaller tables leave grin's times at tens of milliseconds, where the
process's thread start and this VM's noise weigh most.

Prints the evaluations per second of each side and the time ratio at each error; each
setting runs `--repeat` times on both sides and the fastest run counts.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

try:
    import numpy as np
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", "numpy"])
    import numpy as np

N0, A = 1.6, 0.05
LENGTH = 10.0
SCENE = """[camera]
position = [0.0, 0.0, -20.0]
look_at = [0.0, 0.0, 0.0]
fov_y_deg = 30.0

[medium]
bounds = { box = { min = [-2.0, -2.0, 0.0], max = [2.0, 2.0, 10.0] } }
ambient_index = 1.0
field = { kind = "expr", n = "1.6 - 0.05*(x^2 + y^2)" }
"""


def field(r):
    """n and n grad n at the points r (3, N)."""
    x, y = r[0], r[1]
    n = N0 - A * (x * x + y * y)
    d = np.empty_like(r)
    d[0] = n * (-2.0 * A * x)
    d[1] = n * (-2.0 * A * y)
    d[2] = 0.0
    return n, d


def rk4(r, t, h):
    """One RK4 step of (r, T) over t-length h (scalar or per ray)."""
    _, k1 = field(r)
    _, k2 = field(r + 0.5 * h * t)
    t2 = t + 0.5 * h * k1
    _, k3 = field(r + 0.5 * h * t2)
    t3 = t + 0.5 * h * k2
    _, k4 = field(r + h * t3)
    t4 = t + h * k3
    r1 = r + h / 6.0 * (t + 2.0 * t2 + 2.0 * t3 + t4)
    t1 = t + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return r1, t1


def refract(u, normal, n1, n2):
    """Snell's law for unit directions u (3, N) at a face with unit normal (against u)."""
    cos_i = -(u * normal[:, None]).sum(axis=0)
    eta = n1 / n2
    k = 1.0 - eta * eta * (1.0 - cos_i * cos_i)
    return eta * u + (eta * cos_i - np.sqrt(k)) * normal[:, None]


def numpy_trace(origins, dirs, ds):
    """Exit directions of all rays, RK4 at world step ~ds; returns (dirs, evaluations)."""
    u = dirs / np.linalg.norm(dirs, axis=0)
    # Into the z = 0 face.
    s = -origins[2] / u[2]
    r = origins + u * s
    n_in, _ = field(r)
    u_in = refract(u, np.array([0.0, 0.0, -1.0]), 1.0, n_in)
    t = u_in * n_in
    h = ds / N0
    evals = 0
    live = np.arange(r.shape[1])
    out_r = np.empty_like(r)
    out_t = np.empty_like(t)
    while live.size:
        r1, t1 = rk4(r[:, live], t[:, live], h)
        evals += 4 * live.size
        crossed = r1[2] >= LENGTH
        if crossed.any():
            idx = live[crossed]
            # Finish on the face: partial steps from the last state inside, Newton on z.
            r0, t0 = r[:, idx], t[:, idx]
            hp = (LENGTH - r0[2]) / t0[2]
            for _ in range(3):
                rp, tp = rk4(r0, t0, hp)
                evals += 4 * idx.size
                hp = hp - (rp[2] - LENGTH) / tp[2]
            rp, tp = rk4(r0, t0, hp)
            evals += 4 * idx.size
            out_r[:, idx], out_t[:, idx] = rp, tp
        r[:, live], t[:, live] = r1, t1
        live = live[~crossed]
    n_out, _ = field(out_r)
    u_out = out_t / np.linalg.norm(out_t, axis=0)
    return refract(u_out, np.array([0.0, 0.0, -1.0]), n_out, 1.0), evals


def angle(a, b):
    return np.arctan2(np.linalg.norm(np.cross(a.T, b.T), axis=1), (a * b).sum(axis=0))


def grin_trace(grin, scene, table, args, repeat):
    """The exit directions and the summary of the fastest of `repeat` runs."""
    out = table + ".out.csv"
    cmd = [grin, "trace", scene, "--rays", table, "-o", out, "--json"] + args
    summary, whole = None, math.inf
    for _ in range(repeat):
        start = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        whole = min(whole, time.perf_counter() - start)
        if proc.returncode != 0:
            sys.exit(f"grin trace failed: {proc.stderr}")
        run = json.loads(proc.stdout)
        if summary is None or run["seconds"] < summary["seconds"]:
            summary = run
    data = np.genfromtxt(out, delimiter=",", names=True, dtype=None, encoding="utf-8")
    q = np.vstack([data["qx"], data["qy"], data["qz"]]).astype(float)
    return q, summary, whole


def time_at(error, points):
    """Time to reach `error` on a log-log error-versus-time curve (interpolated)."""
    pts = sorted(points, key=lambda p: p[1])
    for (e0, t0), (e1, t1) in zip(pts, pts[1:]):
        if e0 >= error >= e1 or e0 <= error <= e1:
            if e0 == e1:
                return t0
            w = (math.log(error) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + w * (math.log(t1) - math.log(t0)))
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grin", default="target/release/grin")
    ap.add_argument("--rays", type=int, default=100000)
    ap.add_argument("--errors", default="1e-6,1e-9")
    ap.add_argument("--repeat", type=int, default=3,
                    help="runs of each setting on both sides; the fastest counts (this VM's "
                         "timings vary by 20%% run to run)")
    ap.add_argument("--json", action="store_true")
    opts = ap.parse_args()
    rng = np.random.default_rng(1)
    m = opts.rays
    origins = np.vstack([rng.uniform(-1.5, 1.5, m), rng.uniform(-1.5, 1.5, m), -np.ones(m)])
    dirs = np.vstack([np.zeros(m), rng.uniform(-0.05, 0.05, m), np.ones(m)])
    work = tempfile.mkdtemp(prefix="grin-bench-numpy-")
    scene = os.path.join(work, "rod.toml")
    table = os.path.join(work, "rays.csv")
    with open(scene, "w") as f:
        f.write(SCENE)
    with open(table, "w") as f:
        f.write("ox,oy,oz,dx,dy,dz\n")
        for i in range(m):
            f.write(",".join(repr(float(v)) for v in (*origins[:, i], *dirs[:, i])) + "\n")

    ref, _ = numpy_trace(origins.copy(), dirs.copy(), 0.1 / 64)
    rows = []
    numpy_pts, grin_pts = [], []
    for ds in (0.4, 0.2, 0.1, 0.05, 0.025):
        secs = math.inf
        for _ in range(opts.repeat):
            start = time.perf_counter()
            q, evals = numpy_trace(origins.copy(), dirs.copy(), ds)
            secs = min(secs, time.perf_counter() - start)
        err = float(angle(q, ref).max())
        numpy_pts.append((err, secs))
        rows.append(("numpy rk4", f"ds={ds}", err, secs, evals / secs))
    for ds in (0.4, 0.2, 0.1, 0.05, 0.025):
        q, s, whole = grin_trace(opts.grin, scene, table, ["--integrator", "rk4", "--step", f"fixed={ds}"],
                                 opts.repeat)
        err = float(angle(q, ref).max())
        grin_pts.append((err, s["seconds"]))
        rows.append(("grin rk4", f"ds={ds}", err, s["seconds"], s["mean_evals"] * m / s["seconds"]))
    for acc in ("1e-5", "1e-7", "1e-9", "1e-11"):
        q, s, whole = grin_trace(opts.grin, scene, table, ["--step", f"auto={acc}"], opts.repeat)
        err = float(angle(q, ref).max())
        rows.append((f"grin auto", f"auto={acc} ({s['integrator']})", err, s["seconds"],
                     s["mean_evals"] * m / s["seconds"]))
    auto_pts = [(r[2], r[3]) for r in rows if r[0] == "grin auto"]
    ratios = []
    for e in (float(x) for x in opts.errors.split(",")):
        tn, tg, ta = time_at(e, numpy_pts), time_at(e, grin_pts), time_at(e, auto_pts)
        ratios.append({"error": e, "numpy_s": tn, "grin_rk4_s": tg, "grin_auto_s": ta,
                       "speedup_rk4": tn / tg if tn and tg else None,
                       "speedup_auto": tn / ta if tn and ta else None})
    if opts.json:
        print(json.dumps({"rays": m, "cpus": os.cpu_count(), "runs": [
            {"method": r[0], "setting": r[1], "error_rad": r[2], "seconds": r[3],
             "evals_per_second": r[4]} for r in rows], "at_equal_error": ratios}, indent=1))
        return
    print(f"{m} rays, exit-direction error against numpy RK4 at ds = 0.1/64; "
          f"numpy on one core, grin on {os.cpu_count()}")
    print(f"{'method':<11}{'setting':<26}{'error (rad)':>12}{'seconds':>10}{'M evals/s':>11}")
    for r in rows:
        print(f"{r[0]:<11}{r[1]:<26}{r[2]:>12.2e}{r[3]:>10.3f}{r[4] / 1e6:>11.1f}")
    for q in ratios:
        def fmt(v):
            return "n/a" if v is None else f"{v:.2f}x"
        print(f"at error {q['error']:.0e}: grin rk4 {fmt(q['speedup_rk4'])} as fast as numpy, "
              f"grin auto {fmt(q['speedup_auto'])}")


if __name__ == "__main__":
    main()

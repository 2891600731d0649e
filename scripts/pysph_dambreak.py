#!/usr/bin/python3
"""The thesis dam break in PySPH (Debian python3-pysph), as an outside reference for
scripts/bench-grids.py --pysph: the same water column (1.2 x 0.6 m at scale 1, 7381 fluid
particles at dx = 0.01), tank (3.22 m), spacing, time step (1e-4 s), speed of sound (50 m/s),
artificial viscosity (alpha 0.2) and support (quintic spline, 3h = 4 dx) as `sph --setup
dambreak`; walls are PySPH's own (3 layers of boundary particles, dynamic density). PySPH's
shipped dam_break_2d example sets h and m for dx = 0.03 whatever --dx says; here both follow dx.

    /usr/bin/python3 scripts/pysph_dambreak.py --scale 1 --steps 200 --threads 1

Runs the case three times: --warm-steps to compile PySPH's generated code (cached in
~/.pysph), then --warm-steps and --warm-steps + --steps, and prints one JSON line: the
difference of the last two wall times is the cost of --steps steps alone, without set-up.
PySPH's WCSPH scheme integrates with a predictor-corrector: 2 force evaluations per step
(sph: 1), reported as `evaluations_per_step`.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

DX = 0.01
DT = 1e-4
RHO0 = 1000.0
C0 = 50.0
ALPHA = 0.2
GAMMA = 7.0
G = 9.81
TANK_M, DAM_W_M, DAM_H_M = 3.22, 1.2, 0.6
SUPPORT_SPACINGS = 4.0  # 3h = 4 dx, as sph's cell size


def run_case(scale, steps, threads):
    """Child process: one PySPH run of `steps` steps; prints the fluid count and the wall time."""
    import numpy as np
    from pysph.base.kernels import QuinticSpline
    from pysph.base.utils import get_particle_array
    from pysph.solver.application import Application
    from pysph.sph.integrator import PECIntegrator
    from pysph.sph.scheme import WCSPHScheme
    from pysph.tools.geometry import get_2d_tank

    h = SUPPORT_SPACINGS * DX / 3.0
    m = DX * DX * RHO0
    tank, width, height = TANK_M * scale, DAM_W_M * scale, DAM_H_M * scale

    class DamBreak(Application):
        def create_scheme(self):
            return WCSPHScheme(["fluid"], ["boundary"], dim=2, rho0=RHO0, c0=C0, h0=h, hdx=1.0,
                               gy=-G, alpha=ALPHA, beta=0.0, gamma=GAMMA)

        def configure_scheme(self):
            self.scheme.configure_solver(kernel=QuinticSpline(dim=2),
                                         integrator_cls=PECIntegrator, dt=DT, tf=steps * DT,
                                         adaptive_timestep=False, pfreq=10**9)

        def create_particles(self):
            n_x, n_y = int(round(width / DX)) + 1, int(round(height / DX)) + 1
            xf, yf = np.meshgrid(np.arange(n_x) * DX, np.arange(n_y) * DX)
            xt, yt = get_2d_tank(dx=DX, length=tank + 2 * DX, height=2 * height,
                                 base_center=[tank / 2, -DX], num_layers=3)
            fluid = get_particle_array(name="fluid", x=xf.ravel(), y=yf.ravel(), h=h, m=m,
                                       rho=RHO0)
            boundary = get_particle_array(name="boundary", x=xt, y=yt, h=h, m=m, rho=RHO0)
            self.scheme.setup_properties([fluid, boundary])
            return [fluid, boundary]

    out = tempfile.mkdtemp(prefix="pysph_dambreak_")
    args = ["--disable-output", "-d", out, "-q"] + (["--openmp"] if threads > 1 else [])
    app = DamBreak(fname="dam_break", output_dir=out)
    t0 = time.perf_counter()
    app.run(args)
    wall = time.perf_counter() - t0
    fluid = next(pa for pa in app.particles if pa.name == "fluid")
    return {"fluid": int(fluid.get_number_of_particles()), "wall_s": wall,
            "steps_done": int(app.solver.count), "front_x_m": float(fluid.x.max())}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("--scale", type=float, default=1.0, help="geometry scale, as sph --scale")
    ap.add_argument("--steps", type=int, default=200, help="steps timed")
    ap.add_argument("--warm-steps", type=int, default=20,
                    help="steps of the first run, whose wall time (set-up, compilation) is "
                         "subtracted")
    ap.add_argument("--threads", type=int, default=1, help="OpenMP threads (PySPH --openmp)")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args()
    for name in ("scale",):
        v = getattr(a, name)
        if not (math.isfinite(v) and v > 0):
            sys.exit(f"pysph_dambreak: --{name} {v} must be a finite number > 0")
    for name in ("steps", "warm_steps", "threads"):
        if getattr(a, name) < 1:
            sys.exit(f"pysph_dambreak: --{name.replace('_', '-')} {getattr(a, name)} must be >= 1")
    if a.child is not None:
        print(json.dumps(run_case(a.scale, a.child, a.threads)))
        return
    env = dict(os.environ, OMP_NUM_THREADS=str(a.threads))
    runs = []
    # Each run in its own process: PySPH's solver keeps global state between runs. The first
    # compiles (or finds in its cache) the generated code and is not used.
    for steps in (a.warm_steps, a.warm_steps, a.warm_steps + a.steps):
        cmd = [sys.executable, os.path.abspath(__file__), "--scale", str(a.scale), "--threads",
               str(a.threads), "--child", str(steps)]
        r = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if r.returncode != 0:
            tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
            sys.exit(f"pysph_dambreak: PySPH failed ({' '.join(cmd)}): {tail}")
        runs.append(json.loads(r.stdout.strip().splitlines()[-1]))
    runs = runs[1:]
    timed_s = runs[1]["wall_s"] - runs[0]["wall_s"]
    steps = runs[1]["steps_done"] - runs[0]["steps_done"]
    if timed_s <= 0 or steps <= 0:
        sys.exit(f"pysph_dambreak: the longer run was not slower ({runs}); raise --steps")
    print(json.dumps({"code": "pysph", "scale": a.scale, "threads": a.threads,
                      "fluid": runs[1]["fluid"], "steps": steps, "step_s": timed_s / steps,
                      "particle_steps_per_s": runs[1]["fluid"] * steps / timed_s,
                      "evaluations_per_step": 2, "front_x_m": runs[1]["front_x_m"]}))


if __name__ == "__main__":
    main()

"""A parameter sweep: the steady-state yaw-rate gain at 20 m/s over the vehicle's mass, measured
in lockstep and next to the linear bicycle model's V / (L + K V^2), K = (m / L)(b / Cf - a / Cr).

    vdyn-server --lockstep --world flat --model paper &
    python3 mass_sweep.py [--domain 0] [--out mass_sweep.png]
"""

import numpy as np

import vdyn
from _common import connect, figure, options, result, yaw_gain

SPEED = 20.0  # m/s


def main():
    ap = options(__doc__.splitlines()[0], "mass_sweep.png")
    ap.add_argument("--masses", default="1000,1300,1600,1900,2200", help="kg, comma-separated")
    args = ap.parse_args()
    sim = connect(args)
    vid = args.vehicle_id
    delta = np.radians(0.5)
    masses = [float(m) for m in args.masses.split(",")]
    measured, closed = [], []
    start = sim.params(vid)
    for mass in masses:
        # Linear tires and rear drive, as the closed form assumes; the inertias scale with mass.
        k = mass / start.mass
        sim.set_params(vid, {"mass": mass, "ixx": start.ixx * k, "iyy": start.iyy * k,
                             "izz": start.izz * k, "drive_front_fraction": 0.0,
                             "rolling_resistance": 0.0, "tire_law": "TIRE_LAW_LINEAR_SATURATED"})
        params = sim.params(vid)
        sim.teleport(vid, sim.world.spawn.x, sim.world.spawn.y, yaw=0.0, speed=SPEED)
        inp = vdyn.make_input(steer=delta, cruise_kmh=SPEED * 3.6)
        sim.step(12000, inp, vehicle_id=vid)
        s = sim.step(2000, inp, vehicle_id=vid)[vid]
        measured.append(float(np.mean(s.yaw_rate)) / delta)
        closed.append(yaw_gain(params, float(np.mean(np.hypot(s.vxW_mps, s.vyW_mps)))))
        print(f"mass {mass:6.0f} kg: r/delta {measured[-1]:.4f} 1/s, closed form "
              f"{closed[-1]:.4f} 1/s ({100 * (measured[-1] / closed[-1] - 1):+.2f} %)")
    plt = figure()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.plot(masses, measured, "o-", label="measured (lockstep)")
    ax.plot(masses, closed, "s--", label="linear bicycle model V / (L + K V^2)")
    ax.set_xlabel("mass, kg")
    ax.set_ylabel("yaw-rate gain r / delta, 1/s")
    ax.set_title(f"Mass sweep: steady yaw-rate gain at {SPEED:g} m/s - {sim.world_name}")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"figure: {args.out}")
    result(masses=masses, measured=measured, closed=closed)


if __name__ == "__main__":
    main()

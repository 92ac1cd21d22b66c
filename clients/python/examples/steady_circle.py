"""Steady-state circular driving (ISO 4138, constant steer angle method): the understeer
gradient measured next to the linear bicycle model's closed form from the vehicle's parameters.

The car drives at a fixed road-wheel angle at several held speeds; at each, once steady, the
lateral acceleration ay = r V and the path radius R = V / r are read. The steer angle splits into
the Ackermann angle L / R and the rest, K ay: the slope of (delta - L / R) over ay is the
understeer gradient K, compared with K = (m / L) (b / Cf - a / Cr) from the parameters the
server publishes. Best with the paper model (`--model paper`), whose tires are linear at small
slip; the full model adds load transfer, steering compliance and Ackermann geometry.

    vdyn-server --lockstep --world flat --model paper &
    python3 steady_circle.py [--domain 0] [--out steady_circle.png]
"""

import numpy as np

import vdyn
from _common import axle_geometry, connect, figure, options, result, understeer_gradient

G = 9.80665


def circle(sim, vid, delta, speed, settle_s=15.0, measure_s=2.0):
    x0, y0 = sim.world.spawn.x, sim.world.spawn.y
    sim.teleport(vid, x0, y0, yaw=0.0, speed=speed)
    inp = vdyn.make_input(steer=delta, cruise_kmh=speed * 3.6)
    sim.step(int(settle_s / sim.step_s), inp, vehicle_id=vid)
    s = sim.step(int(measure_s / sim.step_s), inp, vehicle_id=vid)[vid]
    v = float(np.mean(np.hypot(s.vxW_mps, s.vyW_mps)))
    r = float(np.mean(s.yaw_rate))
    return v, r


def main():
    ap = options(__doc__.splitlines()[0], "steady_circle.png")
    ap.add_argument("--steer-deg", type=float, default=0.5, help="road-wheel angle (default 0.5)")
    args = ap.parse_args()
    sim = connect(args)
    vid = args.vehicle_id
    # The closed form assumes linear tires and no drive force on the steered wheels.
    sim.set_params(vid, {"drive_front_fraction": 0.0, "rolling_resistance": 0.0,
                         "tire_law": "TIRE_LAW_LINEAR_SATURATED"})
    params = sim.params(vid)
    L = axle_geometry(params)[0]
    K_closed = understeer_gradient(params)
    delta = np.radians(args.steer_deg)
    speeds = [8.0, 12.0, 16.0, 20.0, 24.0]
    ay, excess = [], []
    for speed in speeds:
        v, r = circle(sim, vid, delta, speed)
        ay.append(r * v)
        excess.append(delta - L * r / v)
        print(f"V {v:5.2f} m/s  R {v / r:7.1f} m  ay {r * v:5.2f} m/s^2  "
              f"delta - L/R {np.degrees(excess[-1]):+.4f} deg")
    ay, excess = np.array(ay), np.array(excess)
    K_measured = float(np.polyfit(ay, excess, 1)[0])
    to_deg_per_g = np.degrees(1.0) * G
    print(f"understeer gradient: measured {K_measured * to_deg_per_g:.3f} deg/g, closed form "
          f"{K_closed * to_deg_per_g:.3f} deg/g ({100 * (K_measured / K_closed - 1):+.1f} %)")

    plt = figure()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.plot(ay, np.degrees(excess), "o", label="measured: delta - L/R")
    a = np.linspace(0, max(ay) * 1.1, 50)
    ax.plot(a, np.degrees(K_measured * a + np.polyfit(ay, excess, 1)[1]), "-",
            label=f"fit: K = {K_measured * to_deg_per_g:.3f} deg/g")
    ax.plot(a, np.degrees(K_closed * a), "--",
            label=f"closed form (m/L)(b/Cf - a/Cr) = {K_closed * to_deg_per_g:.3f} deg/g")
    ax.set_xlabel("lateral acceleration, m/s^2")
    ax.set_ylabel("steer angle beyond Ackermann, deg")
    ax.set_title(f"Steady-state circle (ISO 4138), constant steer {args.steer_deg:g} deg - "
                 f"{sim.world_name}")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"figure: {args.out}")
    result(K_measured=K_measured, K_closed=K_closed, ay=ay.tolist())


if __name__ == "__main__":
    main()

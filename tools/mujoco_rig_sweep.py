#!/usr/bin/env python3
"""Sine sweeps of the paper's rig made by another simulator: MuJoCo integrates the output
pulley (its inertia, its shaft's viscous damping and, with --frictionloss, MuJoCo's own
dry friction, a soft constraint rather than longreach's tanh law); the ropes are elastic
(stainless1, k1 = 1.37e5 N per unit strain) on a constant-force tensioner, written here
in closed form. Nothing of longreach's code is used: the datasets are data longreach did
not make, in the measured-data format (docs/models.md, "An independent simulator").

A massless constant-force carriage keeps tension_1 + tension_2 = 2 T0 while both ropes
are taut; when one goes slack the other carries 2 T0. With the stretch difference
d = r1 theta - r2 phi and the rope rate K = k1 / L the output pulley feels

    tau = r2 * clamp(2 K d, -2 T0, 2 T0),   T1 = T0 + tau / (2 r2),  T2 = 2 T0 - T1

The input pulley follows the command exactly (a kinematic drive); the encoders
quantise both angles to 0.18 deg, the load cells add Gaussian noise.

With --stiffening E_S each rope's law is T = k1 e (1 + e / E_S) (tangent stiffness
k1 (1 + 2 e / E_S), which grows as the square root of the tension: not the catalog's
stiffening, linear in the tension); the carriage's take-up c is then solved at every
step from T(c + d) + T(c - d) = 2 T0 (Newton from the last step's c).

With --encoder-delay TAU the output encoder reports the pulley's angle TAU late
(linear interpolation between MuJoCo's steps; before t = 0, the rest angle 0).

With --load-inertia J the output is two inertias, the pulley (I - J) and a load J
behind a torsional shaft (--shaft-stiffness, --shaft-damping): a second mode that no
effect of the catalog holds; the encoder reads the pulley.

Usage (needs `pip install mujoco==4.0.0 numpy`):
    mujoco_rig_sweep.py --out DIR [--frictionloss N_M] [--tensions 49,98,196,294,392]
                        [--seed S] [--dt 2e-4] [--tension-noise 0.5]
                        [--load-inertia J --shaft-stiffness K --shaft-damping C]
                        [--true-damping C_TRUE] [--stiffening E_S]
                        [--encoder-delay TAU]
"""

import argparse
import math
import os
import sys

import mujoco
import numpy as np

R1 = R2 = 0.025
INERTIA = 0.0284
DAMPING = 0.05
LENGTH = 15.2
K1 = 1.37e5
AMPLITUDE = math.radians(4.5)
SETTLE = 3.0
SAMPLE = 0.005
ENCODER = math.radians(0.18)
# the paper's frequency steps (Hz), each held SETTLE s plus at least two cycles (and 5 s)
FREQUENCIES = [0.1, 0.2, 0.4, 0.7, 1.0, 1.4, 1.8, 2.1, 2.4, 2.7, 3.0, 3.3, 3.6, 4.0, 4.5, 5.0, 6.0]

XML = """
<mujoco model="rig_output">
  <option timestep="{dt}" integrator="implicitfast" gravity="0 0 0"/>
  <worldbody>
    <body name="output_pulley">
      <joint name="phi" type="hinge" axis="0 1 0" damping="{damping}" frictionloss="{friction}"/>
      <inertial pos="0 0 0" mass="1" diaginertia="{inertia} {inertia} {inertia}"/>
    </body>
    {load}
  </worldbody>
  {shaft}
</mujoco>
"""

# With --load-inertia: the output pulley (its share I - I_load) drives a load of
# inertia I_load through a torsional shaft of stiffness k_s (a second mode the
# catalog has no effect for); the encoder reads the pulley.
LOAD = """<body name="load">
      <joint name="psi" type="hinge" axis="0 1 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="{i} {i} {i}"/>
    </body>"""
SHAFT = """<tendon>
    <fixed name="shaft" stiffness="{k}" damping="{c}">
      <joint joint="phi" coef="1"/>
      <joint joint="psi" coef="-1"/>
    </fixed>
  </tendon>"""


def schedule():
    """(start time, duration, frequency, phase at the start) of every step; the run's
    length."""
    steps, t, phase = [], 0.0, 0.0
    for f in FREQUENCIES:
        d = max(5.0, SETTLE + 2.0 / f)
        d = math.ceil(d / SAMPLE) * SAMPLE
        steps.append((t, d, f, phase))
        t += d
        phase += 2.0 * math.pi * f * d
    return steps, t


def command(t, steps):
    """Commanded angle and frequency at time t: a sine whose phase is continuous across
    steps (the last step's beyond the schedule)."""
    for start, d, f, phase in steps:
        if t < start + d:
            break
    return AMPLITUDE * math.sin(phase + 2.0 * math.pi * f * (t - start)), f


def quantise(a):
    """An encoder's reading of angle a."""
    return round(a / ENCODER) * ENCODER


def rope_torque(theta, phi, t0):
    k = K1 / LENGTH
    d = R1 * theta - R2 * phi
    pull = min(max(2.0 * k * d, -2.0 * t0), 2.0 * t0)
    return R2 * pull, t0 + 0.5 * pull


class StiffeningRopes:
    """Two ropes of law T = k1 e (1 + e / e_s) (e > 0; slack below) on the constant-force
    carriage: rope 1 stretched by c + d, rope 2 by c - d, with c such that
    T(c + d) + T(c - d) = 2 T0 (one rope carries 2 T0 alone when the other is slack)."""

    def __init__(self, t0, e_s):
        self.t0, self.e_s = t0, e_s
        # the rest take-up: both ropes at T0, T(c) = T0 solved in closed form
        e = 0.5 * e_s * (math.sqrt(1.0 + 4.0 * t0 / (K1 * e_s)) - 1.0)
        self.c = e * LENGTH

    def law(self, stretch):
        """Tension and its derivative with respect to the stretch."""
        if stretch <= 0.0:
            return 0.0, 0.0
        e = stretch / LENGTH
        return K1 * e * (1.0 + e / self.e_s), K1 * (1.0 + 2.0 * e / self.e_s) / LENGTH

    def torque(self, theta, phi):
        """(torque on the output pulley, T1, T2); moves the take-up c."""
        d = R1 * theta - R2 * phi
        c = self.c
        for _ in range(50):
            (f1, g1), (f2, g2) = self.law(c + d), self.law(c - d)
            r = f1 + f2 - 2.0 * self.t0
            if abs(r) <= 1e-10 * self.t0:
                break
            g = g1 + g2
            # (both slack: a step of the rest take-up's order)
            c = c - r / g if g > 0.0 else c + abs(d) + self.c
        else:
            sys.exit(f"the carriage's take-up did not converge at d = {d} m")
        self.c = c
        t1, t2 = self.law(c + d)[0], self.law(c - d)[0]
        return R2 * (t1 - t2), t1, t2


def run(t0, dt, friction, rng, tension_noise, load_inertia, shaft_k, shaft_c, damping, e_s, delay):
    load = LOAD.format(i=load_inertia) if load_inertia > 0.0 else ""
    shaft = SHAFT.format(k=shaft_k, c=shaft_c) if load_inertia > 0.0 else ""
    model = mujoco.MjModel.from_xml_string(
        XML.format(
            dt=dt,
            damping=damping,
            friction=friction,
            inertia=INERTIA - load_inertia,
            load=load,
            shaft=shaft,
        )
    )
    data = mujoco.MjData(model)
    steps, total = schedule()
    n = int(round(total / SAMPLE))
    per = int(round(SAMPLE / dt))  # (main checked that dt divides the sample period)
    ropes = StiffeningRopes(t0, e_s) if e_s is not None else None
    # the pulley's angle at every MuJoCo step so far (for the encoder's delay)
    history = [0.0]

    def tensions(theta, phi):
        if ropes is None:
            tau, t1 = rope_torque(theta, phi, t0)
            return tau, t1, 2.0 * t0 - t1
        return ropes.torque(theta, phi)

    def encoder(t):
        """The pulley's angle the encoder reports at t (history up to t)."""
        back = (t - delay) / dt
        if back <= 0.0:
            return 0.0
        j = int(math.floor(back))
        a = back - j
        return history[j] if a == 0.0 else (1.0 - a) * history[j] + a * history[j + 1]

    rows = []
    for i in range(n):
        t = i * SAMPLE
        theta, f = command(t, steps)
        _, t1, t2 = tensions(theta, data.qpos[0])
        noise = rng.normal(0.0, tension_noise, 4)
        phi = data.qpos[0] if delay == 0.0 else encoder(t)
        rows.append(
            (t, f, theta, quantise(theta), quantise(phi), t1 + noise[0], t2 + noise[1], t1 + noise[2], t2 + noise[3])
        )
        for k in range(per):
            # the rope torque at the step's midpoint input and its start angle
            th, _ = command(t + (k + 0.5) * dt, steps)
            tau, _, _ = tensions(th, data.qpos[0])
            data.qfrc_applied[0] = tau
            mujoco.mj_step(model, data)
            if not math.isfinite(data.qpos[0]):
                sys.exit(f"MuJoCo blew up at t = {t} s")
            if delay > 0.0:
                history.append(data.qpos[0])
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--frictionloss", type=float, default=0.0, help="MuJoCo dry friction on the output shaft [N*m]")
    ap.add_argument("--tensions", default="49,98,196,294,392")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--dt", type=float, default=2e-4)
    ap.add_argument("--tension-noise", type=float, default=0.5)
    ap.add_argument("--load-inertia", type=float, default=0.0, help="part of I behind a torsional shaft [kg*m^2]")
    ap.add_argument("--shaft-stiffness", type=float, default=40.0, help="the shaft's k_s [N*m/rad]")
    ap.add_argument("--shaft-damping", type=float, default=0.01, help="the shaft's damping [N*m*s/rad]")
    ap.add_argument(
        "--true-damping",
        type=float,
        default=None,
        help="the output shaft's viscous damping MuJoCo simulates [N*m*s]; the dataset states C = 0.05",
    )
    ap.add_argument(
        "--stiffening",
        type=float,
        default=None,
        help="E_S: each rope's law is T = k1 e (1 + e / E_S) instead of k1 e [-]",
    )
    ap.add_argument("--encoder-delay", type=float, default=0.0, help="the output encoder reports the angle this late [s]")
    a = ap.parse_args()
    # (every argument checked before anything is written)
    if not 0.0 <= a.load_inertia < INERTIA:
        sys.exit(f"--load-inertia must lie in [0, {INERTIA})")
    if not (a.dt > 0.0 and abs(round(SAMPLE / a.dt) * a.dt - SAMPLE) <= 1e-12):
        sys.exit(f"--dt must divide the sample period {SAMPLE} s, got {a.dt}")
    try:
        tensions = [float(x) for x in a.tensions.split(",")]
    except ValueError:
        sys.exit(f"--tensions must be numbers in N separated by commas, got {a.tensions!r}")
    if not all(t > 0.0 and math.isfinite(t) for t in tensions):
        sys.exit(f"--tensions must be positive, got {a.tensions!r}")
    for name in ("frictionloss", "tension_noise", "shaft_stiffness", "shaft_damping"):
        v = getattr(a, name)
        if not (v >= 0.0 and math.isfinite(v)):
            sys.exit(f"--{name.replace('_', '-')} must be >= 0, got {v}")
    if a.true_damping is not None and not (a.true_damping >= 0.0 and math.isfinite(a.true_damping)):
        sys.exit(f"--true-damping must be >= 0, got {a.true_damping}")
    if a.stiffening is not None and not (a.stiffening > 0.0 and math.isfinite(a.stiffening)):
        sys.exit(f"--stiffening must be > 0 (a strain), got {a.stiffening}")
    if not (0.0 <= a.encoder_delay <= 0.2):
        sys.exit(f"--encoder-delay must lie in [0, 0.2] s, got {a.encoder_delay}")
    rng = np.random.default_rng(a.seed)
    os.makedirs(a.out, exist_ok=True)
    load = (
        f"load {a.load_inertia} kg*m^2 on a {a.shaft_stiffness} N*m/rad shaft, "
        if a.load_inertia > 0.0
        else ""
    )
    if a.stiffening is not None:
        load += f"ropes T = k1 e (1 + e / {a.stiffening}), "
    if a.encoder_delay > 0.0:
        load += f"encoder {a.encoder_delay} s late, "
    toml = [
        'format = "longreach-measurement/1"',
        'kind = "sine_sweep"',
        f'title = "MuJoCo {mujoco.__version__} rig, stainless1, frictionloss {a.frictionloss} N*m, {load}seed {a.seed}"',
        "",
        "[rig]",
        'rope = "stainless1"',
        f"rope_length_m = {LENGTH}",
        f"input_radius_m = {R1}",
        f"output_radius_m = {R2}",
        f"output_inertia_kg_m2 = {INERTIA}",
        f"output_damping_n_m_s = {DAMPING}",
        "relay_pulleys = 3",
        "relay_radius_m = 0.025",
        'tensioner = "constant_force"',
    ]
    for j, t0 in enumerate(tensions):
        name = f"run_{j + 1:02d}.csv"
        rows = run(
            t0,
            a.dt,
            a.frictionloss,
            rng,
            a.tension_noise,
            a.load_inertia,
            a.shaft_stiffness,
            a.shaft_damping,
            DAMPING if a.true_damping is None else a.true_damping,
            a.stiffening,
            a.encoder_delay,
        )
        with open(os.path.join(a.out, name), "w") as fh:
            fh.write(
                "time_s,frequency_hz,command_rad,input_angle_rad,output_angle_rad,"
                "tension_in_1_n,tension_in_2_n,tension_out_1_n,tension_out_2_n\n"
            )
            for r in rows:
                fh.write(
                    f"{r[0]:.3f},{r[1]:.2f},{r[2]:.7f},{r[3]:.7f},{r[4]:.7f},"
                    f"{r[5]:.2f},{r[6]:.2f},{r[7]:.2f},{r[8]:.2f}\n"
                )
        toml += [
            "",
            "[[run]]",
            f'file = "{name}"',
            f"mean_tension_n = {t0}",
            f"amplitude_rad = {AMPLITUDE}",
            f"settle_s = {SETTLE}",
        ]
        print(f"{name}: {len(rows)} samples at T0 = {t0} N", file=sys.stderr)
    with open(os.path.join(a.out, "dataset.toml"), "w") as fh:
        fh.write("\n".join(toml) + "\n")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Python/numpy peer of the Rust physics core, for `cargo bench --bench model`.

The implementation a researcher would write: the clutch torque (13) with the equivalent friction
radius (6) by numpy Gauss-Legendre (8 nodes, like the Rust code), its inverse via numpy.roots on the
spring cubic (10), and one full plant derivative (engine, 2 clutches, driveline with one clutch
locked in gear 1, load with grade, 5-state thermal (16), actuators). Also a vectorised numpy torque
over a large array (numpy's best case). Parameters are read from config/params.toml with tomllib.

Prints one JSON object: {"torque_ns": .., "inverse_ns": .., "derivative_ns": .., "torque_vec_ns": ..,
"check": {...}} (ns per call / per element).
"""
import json
import math
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
P = tomllib.loads((ROOT / "config" / "params.toml").read_text())
C = P["clutch"]
GX, GW = np.polynomial.legendre.leggauss(8)
R1, R2 = C["r1_m"], C["r2_m"]
RHO = 0.5 * (R1 + R2) + 0.5 * (R2 - R1) * GX
WQ = 0.5 * (R2 - R1) * GW


def mu_d(th):
    return C["c1"] * math.sin(C["c2_rad_per_c"] * th + C["c3_rad"]) + C["c4"]


def r_mu(w, th):
    mu = C["mu_s"] + (mu_d(th) - C["mu_s"]) * np.cbrt(np.tanh(C["gamma_s_per_m"] * RHO * abs(w)))
    return float(np.dot(WQ, mu * RHO)) / (R2 - R1)


def x_isp(th):
    d = th - C["theta_a_c"]
    return C["x_isp2_mm_per_c2"] * d * d + C["x_isp1_mm_per_c"] * d + C["x_isp0_mm"]


def spring(u_mm):
    u = u_mm * 1e-3
    return C["p3_n_per_m3"] * u**3 + C["p2_n_per_m2"] * u**2 + C["p1_n_per_m"] * u


def u_fs(x, th):
    x0 = x_isp(th)
    return min(max(C["lambda"] * (x - x0), 0.0), C["lambda"] * (C["x_to_max_mm"] - x0))


def torque(x, w, th):
    f = spring(u_fs(x, th))
    if f == 0.0 or w == 0.0:
        return 0.0
    return math.copysign(2.0 * r_mu(w, th) * f, w)


def invert(t, w, th):
    t = abs(t)
    x0 = x_isp(th)
    if t == 0.0:
        return x0, False
    force = t / (2.0 * r_mu(w, th))
    umax = C["lambda"] * (C["x_to_max_mm"] - x0)
    if force >= spring(umax):
        return C["x_to_max_mm"], force > spring(umax)
    roots = np.roots([C["p3_n_per_m3"], C["p2_n_per_m2"], C["p1_n_per_m"], -force])
    u = [r.real for r in roots if abs(r.imag) < 1e-9 * abs(r) + 1e-18 and -1e-12 <= r.real <= umax * 1e-3 + 1e-12][0]
    return x0 + u * 1e3 / C["lambda"], False


def torque_vec(x, w, th):
    """numpy vectorised (13) over arrays x, w, th."""
    d = th - C["theta_a_c"]
    x0 = C["x_isp2_mm_per_c2"] * d * d + C["x_isp1_mm_per_c"] * d + C["x_isp0_mm"]
    u = np.clip(C["lambda"] * (x - x0), 0.0, C["lambda"] * (C["x_to_max_mm"] - x0)) * 1e-3
    f = ((C["p3_n_per_m3"] * u + C["p2_n_per_m2"]) * u + C["p1_n_per_m"]) * u
    mud = C["c1"] * np.sin(C["c2_rad_per_c"] * th + C["c3_rad"]) + C["c4"]
    q = np.cbrt(np.tanh(C["gamma_s_per_m"] * np.abs(w)[:, None] * RHO[None, :])) @ (WQ * RHO) / (R2 - R1)
    rmu = C["mu_s"] * 0.5 * (R1 + R2) + (mud - C["mu_s"]) * q
    return np.sign(w) * 2.0 * rmu * f


D, E, T5, A = P["driveline"], P["engine"], P["thermal5"], P["actuator"]
RPM = math.pi / 30.0
J = np.array([D["j_eq_kgm2"], D["j_c1_kgm2"], D["j_c2_kgm2"],
              D["vehicle_mass_kg"] * D["wheel_radius_m"] ** 2 + D["j_wheels_kgm2"]])


def full_load(w):
    n = w / RPM
    pk, npk = E["peak_torque_nm"], E["peak_speed_rpm"]
    if n <= npk:
        k = (1 - E["torque_at_idle_nm"] / pk) / ((E["idle_speed_rpm"] - npk) / npk) ** 2
    else:
        k = (1 - E["torque_at_cutoff_nm"] / pk) / ((E["cutoff_speed_rpm"] - npk) / npk) ** 2
    t = pk * (1 - k * ((n - npk) / npk) ** 2)
    stall = min(max(n / E["stall_speed_rpm"], 0.0), 1.0)
    cut = min(max(1 - (n - E["cutoff_speed_rpm"]) / E["cutoff_band_rpm"], 0.0), 1.0)
    return max(t, 0.0) * stall * cut


def derivative(s, u):
    """Full plant derivative: clutch 1 locked in gear 1, clutch 2 slipping on a neutral shaft."""
    wf, wc1, wc2, wout, x1, x2, te, iint, pp1, pp2, c1, c2, cd = s
    k1 = D["ratio_g1"] * D["final_drive"]
    slip2 = wf - wc2
    t2 = torque(x2, slip2, c2)
    cap1 = 2 * r_mu(0.0, c1) * spring(u_fs(x1, c1))
    full = full_load(wf)
    n = wf / RPM
    drag = (E["drag0_nm"] + E["drag1_nm_per_krpm"] * max(n, 0) / 1000) * min(max(n / 100, 0), 1)
    e = E["idle_speed_rpm"] * RPM - wf
    di = E["idle_ki_nm_per_rad"] * e
    cmd = max(u["pedal"] * full - (1 - u["pedal"]) * drag, E["idle_kp_nm_per_radps"] * e + iint)
    cmd = min(cmd, full)
    v = D["wheel_radius_m"] * wout
    tl = (D["f0_nm"] * math.tanh(v / D["load_smoothing_m_per_s"]) + D["f1_nm_s_per_m"] * v
          + D["f2_nm_s2_per_m2"] * v * abs(v)
          + D["vehicle_mass_kg"] * D["gravity_m_per_s2"] * math.sin(math.atan(u["grade"])) * D["wheel_radius_m"])
    # Rigid group {f, c1, out} via (22): generalised inertia and torque referred to the flywheel.
    r = np.array([1.0, 1.0, 0.0, 1.0 / k1])
    t = np.array([te - t2, 0.0, t2, -tl])
    a = float(r @ t) / float((r * r) @ J)
    acc = r * a
    acc[2] = t2 / J[2]
    t1 = te - t2 - J[0] * acc[0]
    p1, p2 = 0.0, t2 * slip2
    b1 = 1.0 if u_fs(x1, c1) > 0 else 0.0
    b2 = 1.0 if u_fs(x2, c2) > 0 else 0.0
    th = u["theta_h"]
    dth = [
        T5["alpha1_per_s"] * b1 * (c1 - pp1) + T5["alpha2_per_s"] * (1 - b1) * (th - pp1) + T5["alpha3_k_per_j"] * p1,
        T5["alpha1_per_s"] * b2 * (c2 - pp2) + T5["alpha2_per_s"] * (1 - b2) * (th - pp2) + T5["alpha3_k_per_j"] * p2,
        T5["alpha4_per_s"] * b1 * (pp1 - c1) + T5["alpha5_per_s"] * b1 * (cd - c1) + T5["alpha6_per_s"] * (1 - b1) * (th - c1) + T5["alpha7_k_per_j"] * p1,
        T5["alpha4_per_s"] * b2 * (pp2 - c2) + T5["alpha5_per_s"] * b2 * (cd - c2) + T5["alpha6_per_s"] * (1 - b2) * (th - c2) + T5["alpha7_k_per_j"] * p2,
        T5["alpha5_per_s"] * b1 * (c1 - cd) + T5["alpha5_per_s"] * b2 * (c2 - cd) + T5["alpha8_per_s"] * (2 - b1 - b2) * (th - cd) + T5["alpha9_k_per_j"] * (p1 + p2),
    ]
    dx = [min(max((min(max(ref, A["x_min_mm"]), A["x_max_mm"]) - x) / A["tau_s"], -A["rate_mm_per_s"]), A["rate_mm_per_s"])
          for ref, x in ((u["x1"], x1), (u["x2"], x2))]
    return [acc[0], acc[1], acc[2], acc[3], dx[0], dx[1], (cmd - te) / E["torque_lag_s"], di] + dth + [t1, cap1]


def timeit(fn, n):
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter_ns()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter_ns() - t0) / n)
    return best


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    k1 = D["ratio_g1"] * D["final_drive"]
    state = [250.0, 250.0, 120.0, 250.0 / k1, 6.5, 4.6, 80.0, 0.0, 90.0, 80.0, 120.0, 110.0, 95.0]
    inp = {"pedal": 0.4, "grade": 0.05, "theta_h": 40.0, "x1": 6.5, "x2": 4.7}
    out = {
        "torque_ns": timeit(lambda: torque(5.5, 37.0, 140.0), n),
        "inverse_ns": timeit(lambda: invert(120.0, 37.0, 140.0), n),
        "derivative_ns": timeit(lambda: derivative(state, inp), n // 4),
    }
    m = 200000
    rng = np.random.default_rng(1)
    xs, ws, ths = rng.uniform(3, 7.2, m), rng.uniform(-200, 200, m), rng.uniform(20, 250, m)
    out["torque_vec_ns"] = timeit(lambda: torque_vec(xs, ws, ths), 3) / m
    d = derivative(state, inp)
    out["check"] = {
        "torque_4.8_50_240": torque(4.8, 50.0, 240.0),
        "inverse_120_37_140": invert(120.0, 37.0, 140.0)[0],
        "vec_matches_scalar": bool(abs(torque_vec(np.array([4.8]), np.array([50.0]), np.array([240.0]))[0] - torque(4.8, 50.0, 240.0)) < 1e-9),
        "derivative_w_f": d[0],
        "derivative_t_fc1": d[13],
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()

"""The PID servo law: step response, torque clamping, anti-windup, refusal of bad input."""

import numpy as np
import pytest

from cpg_walker.robot.pid import PidLaw, load_pid_config


def _simulate(pid: PidLaw, target: float, inertia: float, t_end: float, dt: float = 0.002, load: float = 0.0):
    """A rigid joint (inertia, constant load torque) under the law; semi-implicit Euler."""
    q, v, out = 0.0, 0.0, []
    for _ in range(int(t_end / dt)):
        tau = pid.step([target], [0.0], [q], [v], dt)[0]
        v += (tau - load) / inertia * dt
        q += v * dt
        out.append(q)
    return np.array(out)


def test_step_response_overshoot_and_settling():
    # leg servo (kp 100, kd 3) on the reflected rotor inertia + a leg link (~0.02 kg*m^2): 0.1 rad step
    pid = PidLaw(["j"], kp=100.0, ki=0.0, kd=3.0)
    q = _simulate(pid, 0.1, inertia=0.02, t_end=0.5)
    overshoot = (q.max() - 0.1) / 0.1
    assert overshoot < 0.10  # damping ratio ~1: at most 10 % overshoot
    outside = np.flatnonzero(np.abs(q - 0.1) > 0.002)  # 2 % band
    settling = (outside[-1] + 1) * 0.002 if len(outside) else 0.0
    assert settling < 0.15


def test_torque_is_clamped_to_the_motor_limit():
    pid = PidLaw(["a", "b"], kp=1000.0, ki=0.0, kd=0.0, max_torque=9.0)
    tau = pid.step([1.0, -1.0], [0, 0], [0, 0], [0, 0], 0.002)
    np.testing.assert_allclose(tau, [9.0, -9.0])


def test_integral_removes_offset_and_does_not_wind_up():
    pid = PidLaw(["j"], kp=50.0, ki=200.0, kd=2.0, integral_limit=3.0)
    q = _simulate(pid, 0.2, inertia=0.02, t_end=3.0, load=1.0)  # constant 1 N*m load
    assert abs(q[-1] - 0.2) < 1e-3  # the integral cancels the load
    # a target the saturated motor cannot reach: the integral stays bounded by the clamp
    pid.reset()
    for _ in range(5000):
        pid.step([10.0], [0.0], [0.0], [0.0], 0.002)
    assert abs(pid.ki[0] * pid.integral[0]) <= 3.0 + 1e-12
    # conditional integration: while saturated towards the error the integral did not grow at all
    assert pid.integral[0] == 0.0


def test_velocity_limit_gives_no_further_acceleration():
    pid = PidLaw(["j"], kp=100.0, ki=0.0, kd=0.0, max_velocity=5.0)
    assert pid.step([1.0], [0.0], [0.0], [6.0], 0.002)[0] == 0.0  # would push faster: none
    assert pid.step([-1.0], [0.0], [0.0], [6.0], 0.002)[0] < 0.0  # braking is allowed


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_refused(bad):
    pid = PidLaw(["x", "y"], kp=10.0, ki=0.0, kd=1.0)
    with pytest.raises(ValueError, match=r"non-finite.*y"):
        pid.step([0.0, bad], [0, 0], [0, 0], [0, 0], 0.002)
    for bad_dt in (-0.002, np.nan, np.inf):
        with pytest.raises(ValueError, match="dt"):
            pid.step([0, 0], [0, 0], [0, 0], [0, 0], bad_dt)
    with pytest.raises(ValueError, match="expected 2"):
        pid.step([0.0], [0, 0], [0, 0], [0, 0], 0.002)


def test_gains_come_from_the_config_by_group():
    pid = PidLaw.from_config()
    legs = [i for i, n in enumerate(pid.names) if "leg" in n]
    arms = [i for i, n in enumerate(pid.names) if "arm" in n]
    assert len(pid.names) == 25
    assert np.all(pid.kp[legs] == pid.kp[legs[0]]) and pid.kp[legs[0]] > pid.kp[arms[0]] > 0
    cfg = {**load_pid_config(), **{f"{k}.{g}": v for g in ("leg", "arm", "body", "head")
                                   for k, v in (("kp", 1.0), ("kd", 0.1))}, "kp.lleg_joint_4": 7.0}
    pid = PidLaw.from_config(config=cfg)
    assert pid.kp[pid.names.index("lleg_joint_4")] == 7.0 and pid.kp[pid.names.index("rleg_joint_4")] == 1.0
    with pytest.raises(ValueError, match="tail"):
        PidLaw.from_config(config={**cfg, "kp.tail": 1.0})
    with pytest.raises(ValueError, match=r"missing kd\.head"):
        PidLaw.from_config(config={k: v for k, v in cfg.items() if k != "kd.head"})
    with pytest.raises(ValueError):
        PidLaw(["j"], kp=-1.0, ki=0.0, kd=0.0)


def test_first_sample_dt_zero_is_pd_only():
    """dt = 0 (pid_node's first state: no interval yet) gives the PD torque and leaves the integral."""
    pid = PidLaw(["j"], kp=50.0, ki=200.0, kd=2.0, integral_limit=3.0)
    tau = pid.step([0.1], [0.0], [0.0], [0.5], 0.0)
    assert tau[0] == pytest.approx(50.0 * 0.1 - 2.0 * 0.5) and pid.integral[0] == 0.0


def _numba_installed() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


COMPILED = [False, pytest.param(True, marks=pytest.mark.skipif(not _numba_installed(),
                                                               reason="numba is not installed"))]


@pytest.mark.parametrize("compiled", COMPILED)
@pytest.mark.parametrize("ki, max_torque", [(0.0, 9.0), ("mixed", 9.0), (0.0, "some zero")])
def test_stepper_gives_the_checked_step_to_the_last_bit(ki, max_torque, compiled):
    """The loop's lean law (checks once; numpy or compiled) against `step` on random inputs: saturation,
    the velocity limit, exact and signed zeros, (with ki > 0) the integral's conditional growth and clamp,
    and joints without torque (limit 0, where np.clip's result is +0.0)."""
    rng = np.random.default_rng(7)
    n = 25
    names = [f"j{i}" for i in range(n)]
    kw = dict(kp=rng.uniform(0.0, 200.0, n), kd=rng.uniform(0.0, 5.0, n), integral_limit=0.5,
              max_torque=9.0 if max_torque == 9.0 else np.where(np.arange(n) % 4 == 0, 0.0, 9.0),
              max_velocity=5.0,
              ki=0.0 if ki == 0.0 else np.where(rng.random(n) < 0.5, 0.0, rng.uniform(10.0, 300.0, n)))
    ref, lean = PidLaw(names, **kw), PidLaw(names, **kw)
    law = lean.stepper(0.002, compiled=compiled)
    saturated = clamped = 0
    for k in range(400):
        qt, q = rng.normal(0.0, 0.1, (2, n))
        vt, v = rng.normal(0.0, 3.0, (2, n))  # |v| > 5 rad/s now and then: the velocity limit acts
        if k % 5 == 0:  # exact zeros and a -0.0 PD term (-0.0 - 0.0 = -0.0)
            qt[:5], q[:5], vt[:5], v[:5] = -0.0, 0.0, -0.0, 0.0
            qt[5:8] = q[5:8]
        expected = ref.step(qt, vt, q, v, 0.002)
        got = law(qt, vt, q, v)
        assert got.tobytes() == expected.tobytes(), k
        assert lean.integral.tobytes() == ref.integral.tobytes(), k
        saturated += int(np.sum(np.abs(expected) == 9.0))
        clamped += int(np.sum((np.abs(v) > 5.0) & (expected == 0.0)))
    assert saturated > 100 and clamped > 10  # both limits were exercised
    if ki != 0.0:
        assert np.any(ref.integral != 0.0)
    # shared state: the checked step and the lean law continue each other
    qt, vt, q, v = rng.normal(0.0, 0.1, (4, n))
    assert ref.step(qt, vt, q, v, 0.002).tobytes() == lean.step(qt, vt, q, v, 0.002).tobytes()


@pytest.mark.parametrize("compiled", COMPILED)
def test_stepper_refuses_what_step_refuses(compiled):
    pid = PidLaw(["x", "y"], kp=10.0, ki=0.0, kd=1.0)
    with pytest.raises(ValueError, match="dt"):
        pid.stepper(0.0)
    law = pid.stepper(0.002, compiled=compiled)
    zero = np.zeros(2)
    for bad in (np.nan, np.inf, -np.inf):
        for slot in range(4):
            args = [zero.copy() for _ in range(4)]
            args[slot][1] = bad
            with pytest.raises(ValueError, match=r"non-finite.*'y'"):
                law(*args)
    with pytest.raises(ValueError, match="expected 2"):
        law(np.zeros(3), zero, zero, zero)
    # other array-likes take the checked path and give the same torques
    np.testing.assert_array_equal(law([0.1, -0.2], [0, 0], [0, 0], [0, 0]),
                                  pid.step([0.1, -0.2], [0, 0], [0, 0], [0, 0], 0.002))

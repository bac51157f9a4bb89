"""Storage of the learned HOAP-2 controller: the YAML schema of config/cpg_humanoid.yaml, written by
``cpg-walker learn`` and read by cpg_node (every field checked; an error names the file and the key)."""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import yaml

from cpg_walker.cpg.network import CPGParams
from cpg_walker.errors import InputError
from cpg_walker.paths import yaml_error
from cpg_walker.walker.controller import CHAIN, DOFS, HIP2_PAIR, LEG_PHASE, B, HumanoidCPG, HumanoidSettings

SCHEMA_VERSION = 1


def to_dict(ctrl: HumanoidCPG) -> dict:
    """The learned controller as the YAML schema's mapping."""
    net = ctrl.net
    p = net.params

    def fl(a) -> list:
        return [float(v) for v in np.asarray(a).ravel()]

    dofs = {}
    for b, name in enumerate(DOFS):
        dofs[name] = {
            "offset": float(net.offset[b]), "gain": float(net.gain[b]),
            "omega": fl(net.omega[b]), "alpha": fl(ctrl.alpha_learned[b]), "phi": fl(net.phi[b]),
            "x0": fl(ctrl.phase_zero_state[0, b]), "y0": fl(ctrl.phase_zero_state[1, b]),
        }
    return {
        "schema_version": SCHEMA_VERSION,
        "description": "Humanoid CPG (Righetti & Ijspeert, Sec. III) learned from a recorded walk. "
                       "Per DOF: target = offset + gain*sum_i alpha_i*x_i; omega in internal rad/s "
                       "(physical = time_scale*omega); x0, y0 = oscillator state at phase 0 of the "
                       "teaching cycle; phi[0] of a chain child = learned inter-DOF phase (eq 13).",
        "n_oscillators": int(net.N),
        "time_scale": float(net.time_scale[0]),
        "cpg_params": {k: float(getattr(p, k)) for k in ("mu", "gamma", "epsilon", "eta", "tau")},
        "chain": [[DOFS[c], DOFS[q]] for c, q in CHAIN],
        "leg_coupling": {"pair": [DOFS[i] for i in HIP2_PAIR], "phase": float(LEG_PHASE)},
        "settings": {k: (int(v) if isinstance(v, (int, np.integer)) else float(v))
                     for k, v in asdict(ctrl.settings).items()},
        "teaching": ctrl.meta["teaching"],
        "learning": ctrl.meta["learning"],
        "dofs": dofs,
    }

def save(ctrl: HumanoidCPG, path: str | Path) -> Path:
    """Write the learned controller as YAML (the file cpg_node loads)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "# Learned humanoid CPG (cpg-walker learn). Loaded by cpg_node; schema in walker/storage.py.\n"
    text += yaml.safe_dump(to_dict(ctrl), sort_keys=False, default_flow_style=None, width=120)
    path.write_text(text, encoding="utf-8")
    return path


def load(path: str | Path) -> HumanoidCPG:
    """Read a learned controller; ValueError naming the file and the bad field, FileNotFoundError."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"learned CPG file not found: {path} (run 'cpg-walker learn --out DIR')")
    try:
        d = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise InputError(yaml_error(path, exc)) from None
    return from_dict(d, str(path))


def _require(d: dict, key: str, where: str, kind: type | tuple[type, ...]) -> object:
    if not isinstance(d, dict):
        raise InputError(f"{where}: expected a mapping")
    if key not in d:
        raise InputError(f"{where}: missing key '{key}'")
    v = d[key]
    if kind is float:
        kind = (int, float)
    if not isinstance(v, kind) or (isinstance(v, bool) and kind is not bool):
        raise InputError(f"{where}.{key}: expected {getattr(kind, '__name__', 'a number')}, got {v!r}")
    return v


def _numbers(v: object, n: int, where: str) -> np.ndarray:
    if not isinstance(v, list):
        raise InputError(f"{where}: expected a list of {n} numbers, got {type(v).__name__}")
    if len(v) != n:
        raise InputError(f"{where}: has {len(v)} values, expected {n} (n_oscillators)")
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        raise InputError(f"{where}: every value must be a number, got {v!r}")
    arr = np.array(v, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{where}: contains NaN or infinite values")
    return arr


def from_dict(d: object, where: str = "CPG file") -> HumanoidCPG:
    """A learned controller from the YAML mapping, every field checked (errors name the key)."""
    if not isinstance(d, dict):
        raise InputError(f"{where}: expected a YAML mapping at the top level, got {type(d).__name__}")
    ver = _require(d, "schema_version", where, int)
    if ver != SCHEMA_VERSION:
        raise InputError(f"{where}: schema_version {ver} is not supported (this code reads "
                         f"{SCHEMA_VERSION}); re-run 'cpg-walker learn'")
    N = _require(d, "n_oscillators", where, int)
    if N < 1:
        raise InputError(f"{where}.n_oscillators: must be >= 1, got {N}")
    ts = float(_require(d, "time_scale", where, float))
    if not (math.isfinite(ts) and ts > 0):
        raise InputError(f"{where}.time_scale: must be a positive number, got {ts}")
    cp = _require(d, "cpg_params", where, dict)
    params = CPGParams(**{k: float(_require(cp, k, f"{where}.cpg_params", float))
                          for k in ("mu", "gamma", "epsilon", "eta", "tau")}, amplitude_time_constant=0.0)
    chain = _require(d, "chain", where, list)
    expected_chain = [[DOFS[c], DOFS[q]] for c, q in CHAIN]
    if chain != expected_chain:
        raise InputError(f"{where}.chain: {chain!r} is not this controller's coupling {expected_chain!r}")
    leg = _require(d, "leg_coupling", where, dict)
    if _require(leg, "pair", f"{where}.leg_coupling", list) != [DOFS[i] for i in HIP2_PAIR]:
        raise InputError(f"{where}.leg_coupling.pair: must be {[DOFS[i] for i in HIP2_PAIR]}")
    if float(_require(leg, "phase", f"{where}.leg_coupling", float)) != float(LEG_PHASE):
        raise InputError(f"{where}.leg_coupling.phase: must be pi ({LEG_PHASE!r})")
    settings = HumanoidSettings.from_mapping(_require(d, "settings", where, dict), f"{where}.settings")
    if settings.n_oscillators != N:
        raise InputError(f"{where}.settings.n_oscillators ({settings.n_oscillators}) != n_oscillators ({N})")
    teaching = _require(d, "teaching", where, dict)
    for k in ("gait", "cycle_start_s", "cycle_period_s", "recorded_gait_frequency_hz"):
        _require(teaching, k, f"{where}.teaching", str if k == "gait" else float)
    learning = _require(d, "learning", where, dict)
    dofs = _require(d, "dofs", where, dict)
    extra = sorted(set(dofs) - set(DOFS))
    if extra:
        raise InputError(f"{where}.dofs: unknown DOF(s) {extra}; expected {list(DOFS)}")
    arrays = {k: np.empty((B, N)) for k in ("omega", "alpha", "phi", "x0", "y0")}
    offset, gain = np.empty(B), np.empty(B)
    for b, name in enumerate(DOFS):
        w = f"{where}.dofs.{name}"
        entry = _require(dofs, name, f"{where}.dofs", dict)
        offset[b] = float(_require(entry, "offset", w, float))
        gain[b] = float(_require(entry, "gain", w, float))
        if not (math.isfinite(offset[b]) and math.isfinite(gain[b]) and gain[b] != 0):
            raise InputError(f"{w}: offset must be finite and gain finite and non-zero")
        for k in arrays:
            arrays[k][b] = _numbers(_require(entry, k, w, list), N, f"{w}.{k}")
        if np.any(arrays["omega"][b] <= 0):
            raise InputError(f"{w}.omega: learned frequencies must be > 0")
    net = HumanoidCPG.build_network(arrays["omega"], params, ts, offset, gain, alpha0=arrays["alpha"],
                            phi0=arrays["phi"], x0=arrays["x0"], y0=arrays["y0"])
    net.freeze()
    phase_zero = np.stack([arrays["x0"], arrays["y0"]])
    return HumanoidCPG(net, {"teaching": teaching, "learning": learning}, phase_zero, settings)

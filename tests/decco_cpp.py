"""DECCO's own C++ (LucasKolanz/DECCO at commit fae89d3), built with g++ to step small scenes beside
contact_law = "decco-code" (tests/test_decco_cpp.py).

The driver takes DECCO's ``sim_one_step`` verbatim from ``ColliderSingleCore/ColliderSingleCore.cpp``
and its ``Ball_group`` from ``ball_group.hpp``, with the constants of ``dust_const.hpp`` set to the
scene's (G, mu_k as u_s, mu_r as u_r, no van der Waals cohesion: Ha = 0), and switches DECCO's rules
that docs/model.md keeps otherwise, each named in ``SWITCHES``:

- "gravity": gravity between pairs that do not touch (that commit had it off, for dust);
- "velocities": friction and the spring's switch read the half-step velocities v(n+1/2), w(n+1/2)
  at x(n+1) (DECCO reads v(n), w(n) there; physics.md's kick-drift-kick reads the half step);
- "spring": k_in while the normal velocity closes the pair (DECCO: while the distance is shorter
  than at the step before).

What is left is DECCO's contact law itself: the slip's lever arm, its thresholds, its rolling torques.

    source = decco_source()                 # a checkout of the repository (DECCO_SOURCE), or None
    driver = build(source, tmp_path)        # the executable
    x, v, w = run(driver, state, params, steps)

Nothing here is part of the package; the repository is not shipped or fetched by decco-warp.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

COMMIT = "fae89d3"
URL = "https://github.com/LucasKolanz/DECCO"
SWITCHES = ("gravity", "velocities", "spring")

DRIVER = r"""
#include "ball_group.hpp"
#include <cstdio>
#include <sstream>

std::stringstream ballBuffer;
Ball_group* group = nullptr;
#define O (*group)

%(sim_one_step)s

int main(int argc, char** argv)
{
    // argv: state file (n; then R m x y z vx vy vz wx wy wz per line), steps, dt, k_in, k_out
    FILE* in = std::fopen(argv[1], "r");
    int n = 0;
    if (std::fscanf(in, "%%d", &n) != 1) return 2;
    group = new Ball_group(n);
    for (int i = 0; i < n; i++) {
        double r, mass, x, y, z, vx, vy, vz, wx, wy, wz;
        if (std::fscanf(in, "%%lf %%lf %%lf %%lf %%lf %%lf %%lf %%lf %%lf %%lf %%lf", &r, &mass, &x, &y, &z, &vx, &vy, &vz, &wx, &wy, &wz) != 11) return 2;
        O.R[i] = r; O.m[i] = mass; O.moi[i] = O.calc_moi(r, mass);
        O.pos[i] = {x, y, z}; O.vel[i] = {vx, vy, vz}; O.w[i] = {wx, wy, wz};
        O.acc[i] = {0, 0, 0}; O.aacc[i] = {0, 0, 0};
    }
    std::fclose(in);
    for (int e = 0; e < n * (n - 1) / 2; e++) O.distances[e] = 0;
    const int steps = std::atoi(argv[2]);
    kin = std::atof(argv[4]);
    kout = std::atof(argv[5]);
    dt = 0;  // a step of no time: the accelerations at the start, nothing moved
    sim_one_step(false);
    dt = std::atof(argv[3]);
    for (int s = 0; s < steps; s++) sim_one_step(false);
    for (int i = 0; i < n; i++)
        std::printf("%%.17g %%.17g %%.17g %%.17g %%.17g %%.17g %%.17g %%.17g %%.17g\n", O.pos[i].x, O.pos[i].y, O.pos[i].z,
                    O.vel[i].x, O.vel[i].y, O.vel[i].z, O.w[i].x, O.w[i].y, O.w[i].z);
    return 0;
}
"""


def decco_source() -> Path | None:
    """A git checkout of DECCO holding COMMIT: $DECCO_SOURCE, or a blob-less clone into
    ~/.cache/decco-warp/DECCO (its few files fetched on use); None where neither can be had."""
    candidates = [Path(os.environ["DECCO_SOURCE"])] if os.environ.get("DECCO_SOURCE") else []
    cache = Path.home() / ".cache" / "decco-warp" / "DECCO"
    candidates.append(cache)
    for path in candidates:
        if _has_commit(path):
            return path
    if shutil.which("git") is None:
        return None
    try:
        cache.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(["git", "clone", "--quiet", "--filter=blob:none", "--no-checkout", URL, str(cache)],
                       check=True, capture_output=True, timeout=120)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        shutil.rmtree(cache, ignore_errors=True)
        return None
    return cache if _has_commit(cache) else None


def _has_commit(path: Path) -> bool:
    if not (path / ".git").exists() and not (path / "HEAD").exists():
        return False
    result = subprocess.run(["git", "-C", str(path), "cat-file", "-e", f"{COMMIT}^{{commit}}"], capture_output=True)
    return result.returncode == 0


def _show(source: Path, name: str) -> str:
    return subprocess.run(["git", "-C", str(source), "show", f"{COMMIT}:{name}"], check=True, capture_output=True,
                          text=True, timeout=120).stdout  # fmt: skip


def _constant(text: str, name: str, value: float) -> str:
    """``constexpr double NAME = ...;`` of a DECCO constants header set to ``value``."""
    pattern = rf"(constexpr double {name}\s*=\s*)[^;]+;"
    if not re.search(pattern, text):
        raise ValueError(f"no constexpr {name} in DECCO's constants")
    return re.sub(pattern, rf"\g<1>{value!r};", text, count=1)


def sim_one_step(source_text: str, switches=SWITCHES) -> str:
    """DECCO's ``sim_one_step`` from ColliderSingleCore.cpp, with ``switches`` (of SWITCHES) applied."""
    start = source_text.index("void\nsim_one_step(const bool write_step)\n{")
    end = source_text.index("}  // one Step end", start) + 1
    text = source_text[start:end]
    replacements = []
    if "gravity" in switches:
        replacements.append(("totalForceOnA = vdwForceOnA;  // +gravForceOnA;",
                             "totalForceOnA = vdwForceOnA + (G * O.m[A] * O.m[B] / (dist * dist)) * (rVecab / dist);"))  # fmt: skip
    if "velocities" in switches:
        replacements += [("O.vel[B] - O.vel[A]", "O.velh[B] - O.velh[A]"), ("O.w[A] - O.w[B]", "O.wh[A] - O.wh[B]"),
                         ("O.w[A].cross(r_a) - O.w[B].cross(r_a)", "O.wh[A].cross(r_a) - O.wh[B].cross(r_a)")]  # fmt: skip
    if "spring" in switches:
        replacements.append(("if (dist >= oldDist) {", "if ((O.velh[B] - O.velh[A]).dot(rVecab) >= 0) {"))
    for old, new in replacements:
        if old not in text:
            raise ValueError(f"DECCO's sim_one_step has no {old!r}")
        text = text.replace(old, new)
    return text


def build(source: Path, folder: Path, params, switches=SWITCHES) -> Path:
    """The driver for ``params`` (G, mu_k, mu_r; k_in, k_out and dt are given at run time), built
    with g++ in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("ball_group.hpp", "vec3.hpp", "linalg.hpp", "Utils.hpp"):
        (folder / name).write_text(_show(source, name))
    constants = _show(source, "dust_const.hpp")
    for name, value in (("G", params.G), ("u_s", params.mu_k), ("u_r", params.mu_r), ("Ha", 0.0)):
        constants = _constant(constants, name, float(value))
    (folder / "dust_const.hpp").write_text(constants)
    (folder / "driver.cpp").write_text(DRIVER % {"sim_one_step": sim_one_step(_show(source, "ColliderSingleCore/ColliderSingleCore.cpp"), switches)})
    executable = folder / "decco_driver"
    subprocess.run(["g++", "-std=c++20", "-O2", "-ffp-contract=off", "-include", "math.h", "-o", str(executable), str(folder / "driver.cpp")],
                   check=True, capture_output=True, text=True, cwd=folder, timeout=600)  # fmt: skip
    return executable


def run(executable: Path, state, params, steps: int, folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and spins after ``steps`` of DECCO's stepping from ``state``."""
    rows = np.column_stack([state.radii, state.masses, state.positions, state.velocities, state.omegas])
    path = folder / "state.txt"
    path.write_text(f"{state.n}\n" + "\n".join(" ".join(f"{value!r}" for value in row) for row in rows.tolist()) + "\n")
    result = subprocess.run([str(executable), str(path), str(steps), repr(params.dt), repr(params.k_in), repr(params.k_out)],
                            check=True, capture_output=True, text=True, timeout=600)  # fmt: skip
    values = np.array([[float(v) for v in line.split()] for line in result.stdout.strip().splitlines()])
    return values[:, 0:3], values[:, 3:6], values[:, 6:9]

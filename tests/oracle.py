"""An independent float64 NumPy implementation of docs/model.md, the yardstick for the kernels.

Written from docs/model.md directly, one pair at a time, sharing no code with the
kernels.  Slow (a Python loop over contacts) but plain.
"""

import numpy as np


def pair_loop_forces(x, v, w, radii, masses, k_in, restitution, mu_k, mu_r, G, rolling="couple"):
    """Force and torque on every particle, plus each particle's largest pair force and torque.

    Returns (force, torque, force_scale, torque_scale), all float64.
    """
    n = len(radii)
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    force_scale = np.zeros(n)
    torque_scale = np.zeros(n)
    k_out = restitution**2 * k_in
    for i in range(n):
        r = x[i] - x  # r_ij for every j
        d = np.sqrt((r * r).sum(axis=1))
        others = np.arange(n) != i
        # gravity, paper eq. 2: -G m_i m_j / d^2 n
        with np.errstate(divide="ignore", invalid="ignore"):
            pair_gravity = (-G * masses[i] * masses / d**3)[:, None] * r
        pair_gravity[~others] = 0.0
        force[i] += pair_gravity.sum(axis=0)
        force_scale[i] = np.sqrt((pair_gravity**2).sum(axis=1)).max() if n > 1 else 0.0
        touching = np.flatnonzero(others & (radii[i] + radii - d > 0))
        for j in touching:
            nij = r[j] / d[j]
            delta = radii[i] + radii[j] - d[j]
            approaching = np.dot(v[i] - v[j], nij) < 0
            k = k_in if approaching else k_out
            fn = 0.5 * k * delta
            arm_i = -(radii[i] / (radii[i] + radii[j])) * r[j]
            arm_j = (radii[j] / (radii[i] + radii[j])) * r[j]
            g = (v[i] + np.cross(w[i], arm_i)) - (v[j] + np.cross(w[j], arm_j))
            slip = g - np.dot(g, nij) * nij
            # No friction below 1e-10 of the pair's velocity scale (rigid motion: round-off), and its
            # direction the slip projected once more onto the tangent plane.
            scale = np.linalg.norm(v[i]) + np.linalg.norm(v[j]) + np.linalg.norm(w[i]) * radii[i] + np.linalg.norm(w[j]) * radii[j]
            tangent = slip - np.dot(slip, nij) * nij
            sliding = np.linalg.norm(slip) > 1e-10 * scale and np.linalg.norm(tangent) > 0
            f_slide = -mu_k * fn * tangent / np.linalg.norm(tangent) if sliding else np.zeros(3)
            f_pair = fn * nij + f_slide
            t_pair = np.cross(arm_i, f_slide)
            if rolling == "couple":
                rel = w[i] - w[j]
                roll = rel - np.dot(rel, nij) * nij
                rate = np.linalg.norm(roll)
                if rate > 0:
                    reduced = radii[i] * radii[j] / (radii[i] + radii[j])
                    t_pair = t_pair - mu_r * fn * reduced * roll / rate
            elif rolling == "paper":
                direction = np.cross(w[i] - w[j], r[j])
                size = np.linalg.norm(direction)
                if size > 0:
                    f_roll = -mu_r * fn * direction / size
                    if i > j:  # the printed force acts on the lower index, its opposite on the other
                        f_roll = -f_roll
                    f_pair = f_pair + f_roll
                    t_pair = t_pair + np.cross(arm_i, f_roll)
            else:
                raise ValueError(rolling)
            force[i] += f_pair
            torque[i] += t_pair
            force_scale[i] = max(force_scale[i], np.linalg.norm(f_pair + pair_gravity[j]))
            torque_scale[i] = max(torque_scale[i], np.linalg.norm(t_pair))
    return force, torque, force_scale, torque_scale


def energies(x, v, w, radii, masses, k_in, restitution, G):
    """Kinetic, rotational, potential and elastic energy in float64 (docs/model.md conventions)."""
    inertia = 0.4 * masses * radii**2
    kinetic = 0.5 * (masses * (v * v).sum(axis=1)).sum()
    rotational = 0.5 * (inertia * (w * w).sum(axis=1)).sum()
    potential = 0.0
    elastic = 0.0
    n = len(radii)
    for i in range(n - 1):
        r = x[i] - x[i + 1 :]
        d = np.sqrt((r * r).sum(axis=1))
        potential -= (G * masses[i] * masses[i + 1 :] / d).sum()
        delta = radii[i] + radii[i + 1 :] - d
        for jj in np.flatnonzero(delta > 0):
            j = i + 1 + jj
            approaching = np.dot(v[i] - v[j], r[jj] / d[jj]) < 0
            k = k_in if approaching else restitution**2 * k_in
            elastic += 0.25 * k * delta[jj] ** 2
    return kinetic, rotational, potential, elastic


def decco_code_forces(x, v, w, radii, masses, k_in, restitution, mu_k, mu_r, G):
    """Force and torque on every particle by DECCO's code (LucasKolanz/DECCO at fae89d3,
    ColliderSingleCore.cpp, sim_one_step's second pass), transcribed term by term in its own names:
    each pair once as (A, B), A > B, every quantity from A's side.  Two changes, both docs/model.md's:
    gravity between every pair (that commit had it off for dust, with van der Waals cohesion on), and
    the spring's k_in while the pair approaches by its normal velocity (DECCO: while its distance is
    shorter than at the step before).  k_out = restitution^2 k_in (DECCO's cor is restitution^2)."""
    n = len(radii)
    acc_force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    kout = restitution**2 * k_in
    for A in range(1, n):
        for B in range(A):
            sumRaRb = radii[A] + radii[B]
            rVecab = x[B] - x[A]
            rVecba = -rVecab
            dist = np.linalg.norm(rVecab)
            overlap = sumRaRb - dist
            gravForceOnA = (G * masses[A] * masses[B] / (dist * dist)) * (rVecab / dist)
            totalForceOnA = gravForceOnA
            if overlap > 0:
                k = k_in if np.dot(v[B] - v[A], rVecab) < 0 else kout  # the normal velocity's sign
                elasticForceOnA = -k * overlap * 0.5 * (rVecab / dist)
                elastic_force_A_mag = np.linalg.norm(elasticForceOnA)
                r_a = rVecab * radii[A] / sumRaRb
                r_b = rVecba * radii[B] / sumRaRb
                w_diff = w[A] - w[B]
                d_vel = v[B] - v[A]
                frame_A_vel_B = d_vel - np.dot(d_vel, rVecab) * (rVecab / (dist * dist)) - np.cross(w[A], r_a) - np.cross(w[B], r_a)
                slideForceOnA = np.zeros(3)
                rel_vel_mag = np.linalg.norm(frame_A_vel_B)
                if rel_vel_mag > 1e-13:
                    slideForceOnA = mu_k * elastic_force_A_mag * (frame_A_vel_B / rel_vel_mag)
                rollForceA = np.zeros(3)
                if np.linalg.norm(w_diff) > 1e-13:
                    rollForceA = -mu_r * elastic_force_A_mag * np.cross(w_diff, r_a) / np.linalg.norm(np.cross(w_diff, r_a))
                totalForceOnA = gravForceOnA + elasticForceOnA + slideForceOnA
                torque[A] += np.cross(r_a, slideForceOnA + rollForceA)
                torque[B] += np.cross(r_b, -slideForceOnA + rollForceA)
            acc_force[A] += totalForceOnA
            acc_force[B] -= totalForceOnA
    return acc_force, torque


def _rotate(v, axis, sine, cosine):
    """Rodrigues: v turned right-handedly about the unit axis."""
    return cosine * v + sine * np.cross(axis, v) + (1.0 - cosine) * np.dot(axis, v) * axis


def _dashpot(restitution, stiffness, reduced_mass):
    """The linear dashpot that gives a linear spring that restitution (Schwartz et al. 2012 eq. 15)."""
    log = np.log(restitution)
    return -2.0 * log * np.sqrt(stiffness * reduced_mass / (np.pi**2 + log**2))


def ssdem_constants(params):
    """The soft-sphere law's constants of a Params, by the names of docs/model.md."""
    return dict(k_n=params.k_in / 2, k_t=params.k_t_ratio * params.k_in / 2, eps_n=params.restitution, eps_t=params.eps_t,
                mu_s=params.mu_s, mu_r=params.mu_r, mu_t=params.mu_t, beta=params.beta, dt=params.dt, cohesion=params.cohesion)  # fmt: skip


def ssdem_forces(x, v, w, radii, masses, constants, G, springs, regimes=None):
    """Force and torque on every particle by pkdgrav's soft-sphere law as docs/model.md states it
    ("ssdem"), written from its equations: each touching pair once, from its lower index p, with n
    from p to q.  ``springs``: {(p, q): (S, n of the step before, theta_r, theta_t)} of the step before.
    Returns (force, torque, the springs now), float64; appends to ``regimes`` (a list, if given) which
    of the tangential, rolling and twisting springs slid at each contact, as three bools."""
    c = constants
    dt = c["dt"]
    n_particles = len(radii)
    force = np.zeros((n_particles, 3))
    torque = np.zeros((n_particles, 3))
    now = {}
    for p in range(n_particles):
        for q in range(p + 1, n_particles):
            r = x[q] - x[p]
            d = np.linalg.norm(r)
            pull = G * masses[p] * masses[q] / d**3 * r  # gravity on p, towards q
            force[p] += pull
            force[q] -= pull
            overlap = radii[p] + radii[q] - d
            if overlap <= 0:
                continue
            n = r / d
            l_p = (radii[p] ** 2 - radii[q] ** 2 + d * d) / (2 * d)
            l_q = d - l_p
            mu = masses[p] * masses[q] / (masses[p] + masses[q])
            u = v[q] - v[p] + l_q * np.cross(n, w[q]) + l_p * np.cross(n, w[p])
            u_n = np.dot(u, n) * n
            u_t = u - u_n
            c_n = _dashpot(c["eps_n"], c["k_n"], mu)
            c_t = _dashpot(c["eps_t"], c["k_t"], mu)
            radius_r = c["beta"] * radii[p] * radii[q] / (radii[p] + radii[q])
            spin = w[q] - w[p]
            twist_rate = np.dot(n, spin)
            rolling_rate = spin - twist_rate * n + (l_q - l_p) / (2 * l_p * l_q) * np.cross(n, u)
            S, theta_r, theta_t = np.zeros(3), np.zeros(3), 0.0
            if (p, q) in springs:  # carried into the new tangent plane: about the mean normal, then tilted
                S, n_before, theta_r, theta_t = springs[(p, q)]
                mean = (n_before + n) / np.linalg.norm(n_before + n)
                angle = 0.5 * dt * np.dot(w[p] + w[q], mean)
                axis = np.cross(n_before, n)
                carried = []
                for vec in (S, theta_r):
                    vec = _rotate(vec, mean, np.sin(angle), np.cos(angle))
                    if np.linalg.norm(axis) > 0:
                        vec = _rotate(vec, axis / np.linalg.norm(axis), np.linalg.norm(axis), np.dot(n, n_before))
                    carried.append(vec - np.dot(vec, n) * n)
                S, theta_r = carried
            S = S + u_t * dt
            theta_r = theta_r + rolling_rate * dt
            theta_t = theta_t + twist_rate * dt
            f_n = -c["k_n"] * overlap * n + c_n * u_n
            normal = np.linalg.norm(f_n)
            f_t = c["k_t"] * S + c_t * u_t
            slid = [np.linalg.norm(f_t) > c["mu_s"] * normal, False, False]
            if slid[0]:  # Coulomb: the cap along the trial force
                f_t = c["mu_s"] * normal * f_t / np.linalg.norm(f_t)
                S = (f_t - c_t * u_t) / c["k_t"] if c["k_t"] > 0 else np.zeros(3)
            m_r = c["k_n"] * radius_r**2 * theta_r
            slid[1] = np.linalg.norm(m_r) > c["mu_r"] * radius_r * normal
            if slid[1]:
                m_r = c["mu_r"] * radius_r * normal * m_r / np.linalg.norm(m_r)
                theta_r = theta_r - rolling_rate * dt
            else:
                m_r = m_r + c_n * radius_r**2 * rolling_rate
            m_t = 2 * c["k_t"] * radius_r**2 * theta_t
            cap = c["mu_t"] * c["mu_s"] * radius_r * normal
            slid[2] = abs(m_t) > cap
            if slid[2]:
                m_t = np.sign(m_t) * cap
                theta_t = theta_t - twist_rate * dt
            else:
                m_t = m_t + 2 * c_t * radius_r**2 * twist_rate
            couple = m_r + m_t * n
            f_n = f_n + c.get("cohesion", 0.0) * 4 * radius_r**2 * n  # cohesion: towards q, after the caps
            force[p] += f_n + f_t
            force[q] -= f_n + f_t
            torque[p] += l_p * np.cross(n, f_t) + couple
            torque[q] += l_q * np.cross(n, f_t) - couple
            now[(p, q)] = (S, n, theta_r, theta_t)
            if regimes is not None:
                regimes.append(slid)
    return force, torque, now


def ssdem_run(x, v, w, radii, masses, constants, G, steps, regimes=None):
    """``steps`` kick-drift-kick steps of docs/model.md with the soft-sphere law, the forces of each at
    the drifted positions with the half-step velocities, the first at the start with no springs.
    Returns (x, v, w, springs); ``regimes`` as :func:`ssdem_forces`'s, over the steps."""
    x, v, w = x.copy(), v.copy(), w.copy()
    inertia = 0.4 * masses * radii**2
    dt = constants["dt"]
    force, torque, springs = ssdem_forces(x, v, w, radii, masses, constants, G, {})
    for _ in range(steps):
        v = v + 0.5 * dt * force / masses[:, None]
        w = w + 0.5 * dt * torque / inertia[:, None]
        x = x + dt * v
        force, torque, springs = ssdem_forces(x, v, w, radii, masses, constants, G, springs, regimes)
        v = v + 0.5 * dt * force / masses[:, None]
        w = w + 0.5 * dt * torque / inertia[:, None]
    return x, v, w, springs

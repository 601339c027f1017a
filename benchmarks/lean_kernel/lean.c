/* A lean hand-written kernel of the canonical benchmark scene, the yardstick that docs/performance.md
 * compares sphere with: one material, linear spring-dashpot normal law (dashpot at the predicted
 * velocity, never attractive), tangential spring rotated into the contact plane with a Coulomb cap,
 * the force of a contact's first and last step averaged over the step (sphere's contact window,
 * kernels/laws.py), plane walls, gravity, velocity Verlet; scalar code, one thread. It works on sphere's own arrays
 * (positions, velocities, the half neighbour list and its packed springs), so the comparison is of
 * the kernels alone. Built and driven by compare.py; not part of sphere. */
#include <math.h>
#include <stdint.h>

/* First half kick, drift, prediction of the full-step velocity; returns the largest squared
 * displacement since the list was built. */
double lean_kick_drift(int64_t n, double *pos, double *vel, double *angvel, double *vel_pred, double *angvel_pred,
                       const double *force, const double *torque, const double *ref_pos, double dt, double inv_m,
                       double inv_i) {
    double half = 0.5 * dt, worst = 0.0;
    for (int64_t i = 0; i < n; i++) {
        double moved = 0.0;
        for (int a = 0; a < 3; a++) {
            int64_t e = 3 * i + a;
            vel[e] += half * force[e] * inv_m;
            angvel[e] += half * torque[e] * inv_i;
            vel_pred[e] = vel[e] + half * force[e] * inv_m;
            angvel_pred[e] = angvel[e] + half * torque[e] * inv_i;
            pos[e] += dt * vel[e];
            double d = pos[e] - ref_pos[e];
            moved += d * d;
        }
        if (moved > worst) worst = moved;
    }
    return worst;
}

void lean_kick(int64_t n, double *vel, double *angvel, const double *force, const double *torque, double dt,
               double inv_m, double inv_i) {
    double half = 0.5 * dt;
    for (int64_t e = 0; e < 3 * n; e++) {
        vel[e] += half * force[e] * inv_m;
        angvel[e] += half * torque[e] * inv_i;
    }
}

/* The tangential spring x (rotated, grown by the slip vt dt, capped at mu fn; a sticking force
 * weighted by `end` at the parting); returns the force in g. */
static inline void spring(double *x, const double vt[3], const double n[3], const double ut[3], double kt,
                          double ct, double mu, double fn, double dt, double end, double g[3]) {
    double x0 = x[0], x1 = x[1], x2 = x[2];
    double old2 = x0 * x0 + x1 * x1 + x2 * x2;
    if (old2 > 0.0) {
        double dot = x0 * n[0] + x1 * n[1] + x2 * n[2];
        x0 -= dot * n[0]; x1 -= dot * n[1]; x2 -= dot * n[2];
        double new2 = x0 * x0 + x1 * x1 + x2 * x2;
        if (new2 > 0.0 && new2 != old2) {
            double sc = sqrt(old2 / new2);
            x0 *= sc; x1 *= sc; x2 *= sc;
        }
    }
    x0 += vt[0] * dt; x1 += vt[1] * dt; x2 += vt[2] * dt;
    double f0 = -kt * x0 - ct * ut[0], f1 = -kt * x1 - ct * ut[1], f2 = -kt * x2 - ct * ut[2];
    double ft2 = f0 * f0 + f1 * f1 + f2 * f2, cap = mu * fn;
    if (ft2 > cap * cap) {
        double r = cap / sqrt(ft2);
        f0 *= r; f1 *= r; f2 *= r;
        x0 = -f0 / kt; x1 = -f1 / kt; x2 = -f2 / kt;
    } else {
        double weight = ft2 * end * end > cap * cap ? cap / sqrt(ft2) : end;
        f0 *= weight; f1 *= weight; f2 *= weight;
    }
    x[0] = x0; x[1] = x1; x[2] = x2;
    g[0] = f0; g[1] = f1; g[2] = f2;
}

/* Relative velocity at the contact point (v + r (w_i + w_j) x n with one radius r for both, or the
 * particle's alone against a wall), split into its normal speed and tangential part. */
static inline double slip(const double v[3], const double w[3], const double n[3], double r, double t[3]) {
    double s0 = r * w[0], s1 = r * w[1], s2 = r * w[2];
    double u0 = v[0] - (s1 * n[2] - s2 * n[1]), u1 = v[1] - (s2 * n[0] - s0 * n[2]), u2 = v[2] - (s0 * n[1] - s1 * n[0]);
    double un = u0 * n[0] + u1 * n[1] + u2 * n[2];
    t[0] = u0 - un * n[0]; t[1] = u1 - un * n[1]; t[2] = u2 - un * n[2];
    return un;
}

/* The normal force of overlap delta (kn delta - cn un, never attractive) and the spring's growth
 * and end weight: on the first step of a contact (its surfaces closed by more than delta over
 * the step at vn) and on the last one (they will part within it at un), the elastic force is the
 * mean over the step and the dashpot acts from the touch; *grow is the fraction of the step's
 * slip that the contact has lasted, *end the part of the step a sticking force acts before the
 * parting. */
static inline double normal(double kn, double cn, double delta, double vn, double un, double dt, double *grow,
                            double *end) {
    double travel = 0.0, elastic = kn * delta, damper = cn * un;
    *grow = 1.0;
    *end = 1.0;
    if (-vn * dt > delta) {
        travel = -vn * dt;
        *grow = delta / travel;
    } else if (un * dt > delta) {
        travel = un * dt;
        *end = (delta + 0.5 * travel) / travel;
    }
    if (travel > 0.0) {
        double x = delta + 0.5 * travel;
        elastic = 0.5 * kn * x * x / travel;
        if (*grow < 1.0) damper *= x / travel;
    }
    double fn = elastic - damper;
    return fn < 0.0 ? 0.0 : fn;
}

/* Forces and torques of the scene: gravity, every listed pair (pair (i, nbr[i*C+k]) has its spring
 * at hist[start[i]+k]), the walls (gap = sign (x[axis] - coord), spring at wall_hist[i*W+w]). pp:
 * the pair law kn, kt, cn, ct, mu (dashpots with the reduced mass in); pw: the same for walls. */
void lean_forces(int64_t n, int64_t C, const double *pos, const double *vel, const double *angvel,
                 const double *vel_pred, const double *angvel_pred, const int32_t *nbr, const int32_t *nbr_count,
                 const int64_t *start, double *hist, int64_t W, const int64_t *wall_axis, const double *wall_sign,
                 const double *wall_coord, double *wall_hist, double r, double m, const double *g, const double *pp,
                 const double *pw, double dt, double *force, double *torque) {
    double reach2 = 4.0 * r * r;
    for (int64_t i = 0; i < n; i++)
        for (int a = 0; a < 3; a++) {
            force[3 * i + a] = m * g[a];
            torque[3 * i + a] = 0.0;
        }
    for (int64_t i = 0; i < n; i++) {
        const double *xi = pos + 3 * i;
        double f[3] = {force[3 * i], force[3 * i + 1], force[3 * i + 2]};
        double t[3] = {torque[3 * i], torque[3 * i + 1], torque[3 * i + 2]};
        for (int64_t k = 0; k < nbr_count[i]; k++) {
            int64_t j = nbr[i * C + k];
            double *x = hist + 3 * (start[i] + k);
            double d[3] = {xi[0] - pos[3 * j], xi[1] - pos[3 * j + 1], xi[2] - pos[3 * j + 2]};
            double dist2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            if (dist2 >= reach2) {
                x[0] = x[1] = x[2] = 0.0;
                continue;
            }
            double dist = sqrt(dist2), inv = 1.0 / dist;
            double nn[3] = {d[0] * inv, d[1] * inv, d[2] * inv};
            double v[3], w[3], vp[3], wp[3], vt[3], ut[3], e[3], gg[3];
            for (int a = 0; a < 3; a++) {
                v[a] = vel[3 * i + a] - vel[3 * j + a];
                w[a] = angvel[3 * i + a] + angvel[3 * j + a];
                vp[a] = vel_pred[3 * i + a] - vel_pred[3 * j + a];
                wp[a] = angvel_pred[3 * i + a] + angvel_pred[3 * j + a];
            }
            double vn = slip(v, w, nn, r, vt), un = slip(vp, wp, nn, r, ut), grow, end;
            double fn = normal(pp[0], pp[2], 2.0 * r - dist, vn, un, dt, &grow, &end);
            spring(x, vt, nn, ut, pp[1], pp[3], pp[4], fn, dt * grow, end, gg);
            double c[3] = {r * (nn[1] * gg[2] - nn[2] * gg[1]), r * (nn[2] * gg[0] - nn[0] * gg[2]),
                           r * (nn[0] * gg[1] - nn[1] * gg[0])};
            for (int a = 0; a < 3; a++) {
                e[a] = fn * nn[a] + gg[a];
                f[a] += e[a];
                t[a] -= c[a];
                force[3 * j + a] -= e[a];
                torque[3 * j + a] -= c[a];
            }
        }
        for (int64_t q = 0; q < W; q++) {
            int64_t a = wall_axis[q];
            double sign = wall_sign[q], gap = sign * (xi[a] - wall_coord[q]);
            double *x = wall_hist + 3 * (i * W + q);
            if (gap >= r) {
                x[0] = x[1] = x[2] = 0.0;
                continue;
            }
            double nn[3] = {0.0, 0.0, 0.0}, vt[3], ut[3], gg[3];
            nn[a] = sign;
            double vn = slip(vel + 3 * i, angvel + 3 * i, nn, r, vt), grow, end;
            double un = slip(vel_pred + 3 * i, angvel_pred + 3 * i, nn, r, ut);
            double fn = normal(pw[0], pw[2], r - gap, vn, un, dt, &grow, &end);
            spring(x, vt, nn, ut, pw[1], pw[3], pw[4], fn, dt * grow, end, gg);
            f[0] += fn * nn[0] + gg[0]; f[1] += fn * nn[1] + gg[1]; f[2] += fn * nn[2] + gg[2];
            t[0] -= r * (nn[1] * gg[2] - nn[2] * gg[1]);
            t[1] -= r * (nn[2] * gg[0] - nn[0] * gg[2]);
            t[2] -= r * (nn[0] * gg[1] - nn[1] * gg[0]);
        }
        for (int a = 0; a < 3; a++) {
            force[3 * i + a] = f[a];
            torque[3 * i + a] = t[a];
        }
    }
}

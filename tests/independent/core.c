/*
 * Simulation core of the independent maglev log generator (tests/independent).
 *
 * One closed-loop run of the 2-DOF PMLSM stage: the papers' feedback-linearizing output
 * regulator sampled at the control rate on quantized encoder readings, zero-order-held
 * currents, and the plant (papers' force model with its true constants plus optional
 * unmodelled effects) integrated with classical RK4 at n_sub steps per control period.
 * All quantities SI. The Params struct body is generated from the field list in core.py so
 * that Python and C cannot disagree on its layout.
 *
 * Plant state s = (x1, x2, x3, x4, z_h, z_v): encoder-frame gap [m] and its rate [m/s],
 * horizontal position [m] and its rate [m/s], LuGre bristle deflections of the horizontal
 * and vertical guides [m].
 *
 * Compiled with -O2 -ffp-contract=off (no fused multiply-add, no fast-math) so that a seed
 * gives bit-identical results on re-run.
 */
#include <math.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

typedef struct {
/*@FIELDS@*/
} Params;

int params_size(void) { return (int)sizeof(Params); }

#define NSTATE 6
#define NREC 19
#define NAUX 6

/* L1..L4 of the model at gap y for lumped constants C[0..3] (physics.model_functions). */
static void model_L(const Params *p, const double *C, double y, double *L)
{
    const double a = M_PI / p->tau;
    const double e = exp(a * (p->hm + y));
    const double s = 0.5 * (e - 1.0 / e);
    const double c = 0.5 * (e + 1.0 / e);
    const double coth = c / s;
    const double r = p->b0 / (2.0 * y);
    const double gamma1 = 4.0 / M_PI * (r * atan(r) - 0.5 * log1p(r * r));
    const double kc = p->t1 / (p->t1 - y * gamma1);
    const double lam = 1.0 - p->b0 * p->b0 / (4.0 * p->t1 * (y + 0.5 * p->b0 + p->hm / p->mu_rec));
    const double b = p->Bpre / s;
    L[0] = C[0] * lam / (kc * s);
    L[1] = C[1] * lam * b * b;
    L[2] = -C[2] * lam * b * coth / kc;
    L[3] = C[3] * lam * coth * coth / (kc * kc);
}

/* The end effects' loss at distance u [m] inside an end, 1 at the end and beyond, for the
   profiles other than the exponential: 1 = Gaussian exp(-(u/w)^2), 2 = raised cosine over 3 w
   (none further in than 3 w). */
static double end_profile(int profile, double u, double w)
{
    if (u <= 0.0) return 1.0;
    if (profile == 1) return exp(-(u / w) * (u / w));
    if (u >= 3.0 * w) return 0.0;
    return 0.5 * (1.0 + cos(M_PI * u / (3.0 * w)));
}

/* LuGre friction force [N] and bristle rate dz [m/s] at velocity v [m/s], deflection z [m]. */
static double lugre(double Fc, double Fs, double vs, double s0, double s1, double s2, double v, double z,
                    double *dz)
{
    const double w = exp(-(v / vs) * (v / vs));
    const double gss = Fc + (Fs - Fc) * w;
    *dz = v - s0 * fabs(v) * z / gss;
    return s0 * z + s1 * w * (*dz) + s2 * v;
}

/*
 * Right-hand side of the plant. (iq_c, id_c) are the amplifier's output currents in the
 * commanded dq frame; the commutation error rotates them into the motor's true frame. t [s] is
 * the time in the run, for what changes as the rig warms (the magnets' field, the guides'
 * friction; held over each control period by the caller).
 * aux (may be NULL): true gap, actual i_q, actual i_d, horizontal and vertical friction
 * forces [N], magnetic normal force [N].
 */
static void plant_rhs(const Params *p, const double *s, double iq_c, double id_c, double t, double *ds,
                      double *aux)
{
    /* the magnets' temperature rises first-order towards heat_rise: field factor 1 - heat_coef dT(t);
       the guides' friction level changes first-order by the share fh/fv_warm over the run as their
       lubricant warms (each exactly 1 when off) */
    const double warm = p->heat_on ? 1.0 - p->heat_coef * p->heat_rise * (1.0 - exp(-(t + p->heat_t0) / p->heat_tau)) : 1.0;
    const double warm_h = p->fh_warm != 0.0 ? 1.0 + p->fh_warm * (1.0 - exp(-t / p->fh_warm_tau)) : 1.0;
    const double warm_v = p->fv_warm != 0.0 ? 1.0 + p->fv_warm * (1.0 - exp(-t / p->fv_warm_tau)) : 1.0;
    const double x1 = s[0], x2 = s[1], x3 = s[2], x4 = s[3];
    double iq = iq_c * p->com_cos + id_c * p->com_sin;
    double id = id_c * p->com_cos - iq_c * p->com_sin;
    const double Ctrue[4] = {p->C1, p->C2, p->C3, p->C4};
    double L[4];
    double delta = 0.0, slope = 0.0;
    double fB = 1.0, fBt = 1.0, etaT = 1.0, etaA = 1.0, rho = 1.0, sat = 1.0;
    double Fx, Fn, Ffh = 0.0, Ffv = 0.0, Fv = 0.0;
    int k;

    /* offsets of the phase current sensors: each amplifier drives its sensor's reading, the
       actual phase current plus o_k, to the command, so the actual current lacks o_k; in the
       motor's dq frame (002's transform at theta = pi x3 / tau) a vector fixed to the stator */
    /* gain errors of the phase current sensors: amplifier k drives (1 + e_k) i_k to its command
       i_k* = cos(theta + s_k) i_d* - sin(theta + s_k) i_q*, so the motor gets i_k* / (1 + e_k) */
    if (p->csg_on) {
        const double th = M_PI * x3 / p->tau, sh = 2.0 * M_PI / 3.0;
        const double shift[3] = {0.0, -sh, sh};
        double nd = 0.0, nq = 0.0;
        for (k = 0; k < 3; k++) {
            const double c = cos(th + shift[k]), sn = sin(th + shift[k]);
            const double ik = (c * id - sn * iq) / (1.0 + p->csg_error[k]);
            nd += c * ik;
            nq -= sn * ik;
        }
        id = 2.0 / 3.0 * nd;
        iq = 2.0 / 3.0 * nq;
    }
    if (p->cso_on) {
        const double th = M_PI * x3 / p->tau, sh = 2.0 * M_PI / 3.0;
        const double o0 = p->cso_offset[0], o1 = p->cso_offset[1], o2 = p->cso_offset[2];
        id -= 2.0 / 3.0 * (cos(th) * o0 + cos(th - sh) * o1 + cos(th + sh) * o2);
        iq += 2.0 / 3.0 * (sin(th) * o0 + sin(th - sh) * o1 + sin(th + sh) * o2);
    }

    /* guide misalignment: magnetic gap differs from the encoder's reading */
    if (p->mis_on) {
        delta = p->mis_slope * x3;
        slope = p->mis_slope;
        if (p->mis_amp != 0.0) {
            const double kw = 2.0 * M_PI / p->mis_len;
            delta += p->mis_amp * (sin(kw * x3 + p->mis_phase) - sin(p->mis_phase));
            slope += p->mis_amp * kw * cos(kw * x3 + p->mis_phase);
        }
    }
    /* the gap sensor's zero: the magnetic gap is the reading plus gap_zero */
    /* ... and its drift as the frame and the sensor's mount warm (first-order; none when off) */
    const double zero_drift = p->gz_drift != 0.0 ? p->gz_drift * (1.0 - exp(-t / p->gz_drift_tau)) : 0.0;
    const double g = x1 + delta + p->gap_zero + zero_drift;
    model_L(p, Ctrue, g, L);

    /* magnets' field differing smoothly from the closed form */
    if (p->fs_on) {
        const double d = g - p->fs_gref;
        fB = exp(-p->fs_k1 * d - p->fs_k2 * d * d);
        fBt = p->fs_thrust ? fB : 1.0;
    }
    /* the magnets warming: their field, and every force it makes (attraction ~ B^2, thrust and the
       i_d term ~ B), falls with their temperature; the armature's own attraction (L4) does not */
    fB *= warm;
    fBt *= warm;
    /* end effects: smooth loss of thrust and attraction near the stator ends */
    if (p->ee_on) {
        double loss = p->ee_profile == 0 ? exp((x3 - p->ee_xp) / p->ee_w) + exp((p->ee_xm - x3) / p->ee_w)
                                         : end_profile(p->ee_profile, p->ee_xp - x3, p->ee_w) +
                                               end_profile(p->ee_profile, x3 - p->ee_xm, p->ee_w);
        if (loss > 2.0) loss = 2.0;
        etaT = 1.0 - p->ee_fT * loss;
        etaA = 1.0 - p->ee_fA * loss;
    }
    /* thrust ripple */
    if (p->tr_on) {
        for (k = 0; k < 2; k++)
            if (p->tr_amp[k] != 0.0)
                rho += p->tr_amp[k] * cos(2.0 * M_PI * x3 / p->tr_period[k] + p->tr_phase[k]);
    }

    /* iron saturated by the stator current: the armature's flux, and with it the force per
       ampere, falls as 1 / (1 + |i|^2 / I_s^2); exactly 1 (the same arithmetic) when off */
    if (p->sat_on) {
        const double r = (id * id + iq * iq) / (p->sat_current * p->sat_current);
        sat = 1.0 / (1.0 + r);
    }

    Fx = -p->Mh * L[0] * fBt * etaT * rho * (iq * sat);
    Fn = p->Mv * (L[1] * fB * fB * etaA + L[2] * fBt * etaT * (id * sat) +
                  L[3] * etaT * ((id * id + iq * iq) * (sat * sat)));

    /* normal cogging (adds to the attraction) and longitudinal cogging (detent) */
    if (p->cn_on) {
        for (k = 0; k < 3; k++)
            if (p->cn_amp[k] != 0.0)
                Fn += p->cn_amp[k] * exp(-(g - p->cn_gref) / p->cn_decay[k]) *
                      sin(2.0 * M_PI * x3 / p->cn_period[k] + p->cn_phase[k]);
    }
    if (p->cl_on) {
        for (k = 0; k < 3; k++)
            if (p->cl_amp[k] != 0.0)
                Fx += p->cl_amp[k] * exp(-(g - p->cl_gref) / p->cl_decay[k]) *
                      sin(2.0 * M_PI * x3 / p->cl_period[k] + p->cl_phase[k]);
    }
    /* cable carrier, base not level, tilted guide */
    if (p->cab_on) Fx += -p->cab_k * (x3 - p->cab_x0) + p->cab_F0;
    Fx += p->tilt_F;
    if (p->mis_on) Fx += slope * ((p->Mh + p->load) * p->G - Fn);
    /* a force on the vertical axis the magnets must carry besides the weight (a hanging cable's
       weight, a spring between frame and platform): along +x1 (opening the gap) */
    if (p->vf_on) Fv = p->vf_F - p->vf_k * (x1 - p->vf_x0);

    /* guide friction (LuGre) */
    ds[4] = 0.0;
    ds[5] = 0.0;
    /* the sliding forces scaled by the level along the track (horizontal guides: 1 + slope x3) and
       by the direction (1 + asym when moving forward, 1 - asym backward); exactly 1 when off */
    if (p->fh_on) {
        double f = 1.0;
        if (p->fh_slope != 0.0) f *= 1.0 + p->fh_slope * x3;
        if (p->fh_asym != 0.0) f *= x4 > 0.0 ? 1.0 + p->fh_asym : 1.0 - p->fh_asym;
        f *= warm_h;
        Ffh = lugre(f * p->fh_Fc, f * p->fh_Fs, p->fh_vs, p->fh_s0, p->fh_s1, warm_h * p->fh_s2, x4, s[4], &ds[4]);
    }
    if (p->fv_on) {
        const double f = (p->fv_asym == 0.0 ? 1.0 : x2 > 0.0 ? 1.0 + p->fv_asym : 1.0 - p->fv_asym) * warm_v;
        Ffv = lugre(f * p->fv_Fc, f * p->fv_Fs, p->fv_vs, p->fv_s0, p->fv_s1, warm_v * p->fv_s2, x2, s[5], &ds[5]);
    }

    ds[0] = x2;
    /* the forces move the stage and its payload (p->load [kg] on the platform moves with both
       axes); the constants' forces are per the unloaded masses Mh, Mv */
    ds[1] = p->G - (Fn + Ffv - Fv) / (p->Mv + p->load);
    ds[2] = x4;
    ds[3] = (Fx - Ffh) / (p->Mh + p->load);
    if (aux) {
        aux[0] = g;
        aux[1] = iq;
        aux[2] = id;
        aux[3] = Ffh;
        aux[4] = Ffv;
        aux[5] = Fn;
    }
}

/* Feedback transformation with the controller's constants: physical root (SPEC 1 item 5). */
static int control_law(const Params *p, double y1, double v1, double v2, double *u1, double *u2)
{
    const double Cn[4] = {p->Cn1, p->Cn2, p->Cn3, p->Cn4};
    double L[4], R;
    int clipped = 0;
    model_L(p, Cn, y1, L);
    *u1 = -v1 / L[0];
    R = L[2] * L[2] - 4.0 * L[3] * (L[3] * (*u1) * (*u1) + L[1] - p->G + v2);
    if (R < 0.0) {
        R = 0.0;
        clipped = 1;
    }
    *u2 = (-L[2] - sqrt(R)) / (2.0 * L[3]);
    return clipped;
}

static double quantize(double x, double q) { return q * floor(x / q + 0.5); }

static double clip(double u, double lim) { return u > lim ? lim : (u < -lim ? -lim : u); }

/* --- exported helpers for the tests ------------------------------------------------------- */

void eval_rhs(const Params *p, const double *s, double iq_c, double id_c, double t, double *ds, double *aux)
{
    plant_rhs(p, s, iq_c, id_c, t, ds, aux);
}

int eval_control(const Params *p, double y1, double v1, double v2, double *u)
{
    return control_law(p, y1, v1, v2, &u[0], &u[1]);
}

/* The base's acceleration over control period k felt by the stage's coordinates (relative to the
   base, as the encoders measure them): the derivative ds of the velocities less it. */
static void shaken(const Params *p, const double *base_acc, int k, double *ds)
{
    if (!p->vib_on) return;
    ds[1] -= base_acc[2 * k];
    ds[3] -= base_acc[2 * k + 1];
}

/*
 * One closed-loop run.
 *
 * ref    (n_ctrl x 4): r_v, dr_v/dt, r_h, dr_h/dt at the control instants.
 * noise  (n_ctrl x 2): encoder noise [m] added to x1, x3 before quantization.
 * s0     (6): initial plant state.
 * rec    (n_rec x NREC) with n_rec = ceil(n_ctrl / record_every): rows at every record_every-th
 *        control instant: x1 x2 x3 x4 (true), y1 y3 (encoder), u1 u2 (commanded),
 *        iq id (actual), gap (true), F_fric_h F_fric_v [N], v1 v2, xhat2 xhat4, the amplifier's
 *        output iq id in the commanded frame (what its current sensors read; through their
 *        first-order filter when p->sensor_tau > 0).
 * info   (5): status (0 ok, 1 left the stage's range, 2 not finite), control index of failure,
 *        samples with R clipped at 0, samples with a command clipped at i_max, substeps with the
 *        amplifier at its peak.
 * ucmd   (n_ctrl x 2) work space: the commanded (u1, u2) of every control sample.
 * base_acc (n_ctrl x 2): the base's (and the encoders') acceleration, vertical (along +x1) and
 *        horizontal [m/s^2], held over each control period; read only when p->vib_on. The stage's
 *        coordinates are the encoders', relative to the base: they accelerate by minus it.
 */
int simulate(const Params *p, int n_ctrl, const double *ref, const double *noise, const double *s0,
             double *rec, int *info, double *ucmd, const double *base_acc)
{
    const int ns = p->n_sub;
    const double h = p->Tc / ns;
    const double Eh = p->amp_tau > 0.0 ? exp(-0.5 * h / p->amp_tau) : 0.0;
    const double Ef = p->amp_tau > 0.0 ? exp(-h / p->amp_tau) : 0.0;
    double s[NSTATE], st[NSTATE], k1[NSTATE], k2[NSTATE], k3[NSTATE], k4[NSTATE];
    double ov[2] = {0, 0}, oh[2] = {0, 0}; /* observer states (position, velocity) */
    double xiv[3] = {0, 0, 0}, xih[3] = {0, 0, 0};
    double vprev1 = 0.0, vprev2 = 0.0, yprev1 = 0.0, yprev3 = 0.0;
    double ia_q = 0.0, ia_d = 0.0; /* amplifier output (dq, commanded frame) */
    double fs_q = 0.0, fs_d = 0.0; /* its current sensors' filtered reading */
    const double Es = p->sensor_tau > 0.0 ? exp(-h / p->sensor_tau) : 0.0;
    double piv = 0.0, pih = 0.0;   /* the PID loops' error integrals */
    double aux[NAUX];
    int k, j, i, nrec = 0;

    memcpy(s, s0, sizeof(s));
    for (i = 0; i < 5; i++) info[i] = 0;

    for (k = 0; k < n_ctrl; k++) {
        const double rv = ref[4 * k], drv = ref[4 * k + 1], rh = ref[4 * k + 2], drh = ref[4 * k + 3];
        const double tk = k * p->Tc; /* what warms over the run is held over each control period */
        /* encoders */
        const double y1 = quantize(s[0] + noise[2 * k], p->q);
        const double y3 = quantize(s[2] + noise[2 * k + 1], p->q);
        double e1, de1, e2, de2, v1, v2, u1, u2, nv[2], nh[2], nxi[3];

        /* high-gain observers: x_k = Ao x_{k-1} + Bo (y_{k-1}, v_{k-1}) */
        if (k == 0) {
            ov[0] = y1;
            ov[1] = 0.0;
            oh[0] = y3;
            oh[1] = 0.0;
        } else {
            nv[0] = p->Ao[0] * ov[0] + p->Ao[1] * ov[1] + p->Bo[0] * yprev1 + p->Bo[1] * vprev2;
            nv[1] = p->Ao[2] * ov[0] + p->Ao[3] * ov[1] + p->Bo[2] * yprev1 + p->Bo[3] * vprev2;
            nh[0] = p->Ao[0] * oh[0] + p->Ao[1] * oh[1] + p->Bo[0] * yprev3 + p->Bo[1] * vprev1;
            nh[1] = p->Ao[2] * oh[0] + p->Ao[3] * oh[1] + p->Bo[2] * yprev3 + p->Bo[3] * vprev1;
            ov[0] = nv[0];
            ov[1] = nv[1];
            oh[0] = nh[0];
            oh[1] = nh[1];
        }
        e1 = y1 - rv;
        de1 = ov[1] - drv;
        e2 = y3 - rh;
        de2 = oh[1] - drh;
        v2 = p->Kv[0] * e1 + p->Kv[1] * de1 + p->Kv[2] * xiv[0] + p->Kv[3] * xiv[1] + p->Kv[4] * xiv[2];
        v1 = p->Kh[0] * e2 + p->Kh[1] * de2 + p->Kh[2] * xih[0] + p->Kh[3] * xih[1] + p->Kh[4] * xih[2];
        if (p->pid_on) {
            /* two independent PID loops (the papers' identification runs) on the same errors and
               observer velocities; the integrals by the rectangle rule, this sample's error last.
               v1, v2 (what the observers predict with) are the accelerations the loops ask for */
            v2 = -(p->pid_v[0] * e1 + p->pid_v[1] * de1 + p->pid_v[2] * piv);
            v1 = -(p->pid_h[0] * e2 + p->pid_h[1] * de2 + p->pid_h[2] * pih);
            u2 = p->pid_ieq + v2 / p->pid_bv;
            u1 = v1 / p->pid_bh;
            piv += e1 * p->Tc;
            pih += e2 * p->Tc;
        } else {
            info[2] += control_law(p, y1, v1, v2, &u1, &u2);
        }
        if (fabs(u1) > p->i_max || fabs(u2) > p->i_max) info[3]++;
        u1 = clip(u1, p->i_max);
        u2 = clip(u2, p->i_max);
        ucmd[2 * k] = u1;
        ucmd[2 * k + 1] = u2;

        /* internal models: xi_{k+1} = Ai xi_k + Bi e_k */
        for (i = 0; i < 3; i++)
            nxi[i] = p->Ai[3 * i] * xiv[0] + p->Ai[3 * i + 1] * xiv[1] + p->Ai[3 * i + 2] * xiv[2] + p->Bi[i] * e1;
        memcpy(xiv, nxi, sizeof(nxi));
        for (i = 0; i < 3; i++)
            nxi[i] = p->Ai[3 * i] * xih[0] + p->Ai[3 * i + 1] * xih[1] + p->Ai[3 * i + 2] * xih[2] + p->Bi[i] * e2;
        memcpy(xih, nxi, sizeof(nxi));
        vprev1 = v1;
        vprev2 = v2;
        yprev1 = y1;
        yprev3 = y3;

        if (k == 0) {
            /* the amplifier was already delivering the first command before t = 0 */
            ia_q = u1;
            ia_d = u2;
            fs_q = u1;
            fs_d = u2;
        }

        /* plant over [t_k, t_k + Tc) */
        for (j = 0; j < ns; j++) {
            const int jg = k * ns + j - p->amp_delay_sub;
            int kc = jg < 0 ? 0 : jg / ns;
            double cq, cd, mag, iq0, id0, iqh, idh, iq1, id1;
            cq = ucmd[2 * kc];
            cd = ucmd[2 * kc + 1];
            mag = sqrt(cq * cq + cd * cd);
            if (p->amp_peak > 0.0 && mag > p->amp_peak) {
                cq *= p->amp_peak / mag;
                cd *= p->amp_peak / mag;
                info[4]++;
            }
            if (p->amp_tau > 0.0) {
                iq0 = ia_q;
                id0 = ia_d;
                iqh = cq + (ia_q - cq) * Eh;
                idh = cd + (ia_d - cd) * Eh;
                iq1 = cq + (ia_q - cq) * Ef;
                id1 = cd + (ia_d - cd) * Ef;
            } else {
                iq0 = iqh = iq1 = cq;
                id0 = idh = id1 = cd;
            }
            if (j == 0 && k % p->record_every == 0) {
                double *r = rec + (size_t)NREC * nrec++;
                plant_rhs(p, s, iq0, id0, tk, k1, aux);
                r[0] = s[0];
                r[1] = s[1];
                r[2] = s[2];
                r[3] = s[3];
                r[4] = y1;
                r[5] = y3;
                r[6] = u1;
                r[7] = u2;
                r[8] = aux[1];
                r[9] = aux[2];
                r[10] = aux[0];
                r[11] = aux[3];
                r[12] = aux[4];
                r[13] = v1;
                r[14] = v2;
                r[15] = ov[1];
                r[16] = oh[1];
                r[17] = p->sensor_tau > 0.0 ? fs_q : iq0;
                r[18] = p->sensor_tau > 0.0 ? fs_d : id0;
            } else {
                plant_rhs(p, s, iq0, id0, tk, k1, NULL);
            }
            if (p->sensor_tau > 0.0) { /* the sensors' filter over the substep, at its mid current */
                fs_q = iqh + (fs_q - iqh) * Es;
                fs_d = idh + (fs_d - idh) * Es;
            }
            shaken(p, base_acc, k, k1);
            for (i = 0; i < NSTATE; i++) st[i] = s[i] + 0.5 * h * k1[i];
            plant_rhs(p, st, iqh, idh, tk, k2, NULL);
            shaken(p, base_acc, k, k2);
            for (i = 0; i < NSTATE; i++) st[i] = s[i] + 0.5 * h * k2[i];
            plant_rhs(p, st, iqh, idh, tk, k3, NULL);
            shaken(p, base_acc, k, k3);
            for (i = 0; i < NSTATE; i++) st[i] = s[i] + h * k3[i];
            plant_rhs(p, st, iq1, id1, tk, k4, NULL);
            shaken(p, base_acc, k, k4);
            for (i = 0; i < NSTATE; i++) s[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            /* the stopper: a gap beyond it is held there, an opening rate stopped (inelastic) */
            if (p->stop_gap > 0.0 && s[0] > p->stop_gap) {
                s[0] = p->stop_gap;
                if (s[1] > 0.0) s[1] = 0.0;
            }
            /* ... the stop at the smallest gap (the platform against the stator), the end stops of
               the horizontal travel: the same */
            if (p->top_gap > 0.0 && s[0] < p->top_gap) {
                s[0] = p->top_gap;
                if (s[1] < 0.0) s[1] = 0.0;
            }
            if (p->x3_stop_on) {
                if (s[2] > p->x3_stop_hi) {
                    s[2] = p->x3_stop_hi;
                    if (s[3] > 0.0) s[3] = 0.0;
                } else if (s[2] < p->x3_stop_lo) {
                    s[2] = p->x3_stop_lo;
                    if (s[3] < 0.0) s[3] = 0.0;
                }
            }
            ia_q = iq1;
            ia_d = id1;
        }
        for (i = 0; i < NSTATE; i++) {
            if (!isfinite(s[i])) {
                info[0] = 2;
                info[1] = k;
                return 2;
            }
        }
        if (s[0] < p->gap_min || s[0] > p->gap_max || fabs(s[2]) > p->x3_max) {
            info[0] = 1;
            info[1] = k;
            return 1;
        }
    }
    return 0;
}

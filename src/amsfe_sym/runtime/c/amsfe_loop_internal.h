/* amsfe_loop_internal.h: what the files of the compiled loop share inside a generated library
 * (amsfe_ctrl.c: the controllers; amsfe_blend.c: the start-up's blends; amsfe_loop.c: the
 * real-time tick and the closed-loop simulation).  Not part of the public API (not copied
 * next to the library): the generated functions they call and the work arrays sized for
 * them, the controller's object, and the functions one file defines for another (hidden
 * from the exports). */
#ifndef AMSFE_LOOP_INTERNAL_H
#define AMSFE_LOOP_INTERNAL_H

#include "amsfe_internal.h"
#include "amsfe_loop.h"

DECLARE(control_amsfe)
DECLARE(control_dtsmc)
DECLARE(control_amsfe_paper)
DECLARE(control_dtsmc_paper)
DECLARE(plant_step)
DECLARE(camera_measure)
DECLARE(mass_matrix)
DECLARE(bias)
DECLARE(control_motor_reference)

static const cwork WORKS[] = {control_amsfe_work,       control_dtsmc_work,
                              control_amsfe_paper_work, control_dtsmc_paper_work,
                              plant_step_work,          camera_measure_work,
                              mass_matrix_work,         bias_work,
                              control_motor_reference_work};

/* The library's dimensions (amsfe_dims_get) as a value. */
static inline amsfe_dims dims_now(void) {
  amsfe_dims d;
  amsfe_dims_get(&d);
  return d;
}

/* ================================================================== controller */
struct amsfe_ctrl {
  amsfe_ctrl_params par; /* its pointers point into this block */
  amsfe_dims d;
  int p_theta;
  gwork g;
  double *h, *lam, *Lt, *eps, *phi, *wm, *tau_max, *wf, *vmax, *u_max, *Mm, *Fm, *Ks,
      *theta0, *zeros;
  int *ks_theta;
  double pp; /* the terminal power, as a 1-vector input */
  /* memory between ticks */
  long ticks;
  double *u_prev;  /* the last applied (limited) torque */
  double *cf;      /* cascade: command-filter state [2n] */
  int started;     /* cascade: the filter was started on the first (trusted) command */
  int ready;       /* cascade: the start-up's test passed (latched) */
  int observed;    /* amsfe_ctrl_observe ran since the last torque (else: converged) */
  int have_hold;   /* cascade: c_hold was taken */
  double *c_hold;  /* cascade: the motor's offset from qm_r at the first tick [n] */
  double *hold1, *hold0; /* the law's hold input: ones, zeros [n] */
  long blend_k0;   /* cascade: the blended start's first tick (control/blend.py) */
  double blend_s0; /* s at blend_k0 [s] (blend_lead: the plan started that long before) */
  long k_first;    /* the first tick this controller ran (blend_lead) */
  int have_kfirst;
  double blend_tb; /* its duration [s] */
  double *blend_d0, *blend_d1, *refb; /* its offsets [n], [n]; the blended reference [5n] */
  double *blend_e0, *blend_e1; /* blend_lead: the trusted offsets it passes through [n], [n] */
  double *wfb;     /* the command filter's bandwidth while the blend runs (blend_wf) [n] */
  double rho;      /* headroom_tau: the gains' scale (1: unscaled) */
  int have_udem;   /* ... the law's demand u_dem of the last tick it acted is known */
  double *u_dem, *hs, *epss, *wms, *wfs; /* ... that demand, the scaled h, eps, wm, wf [n] */
  double nis_mean; /* cascade: the encoders' mean NIS (running, then exponential window) */
  long nis_count;  /* NIS values taken into it */
  double nis_tick; /* this tick's NIS (amsfe_ctrl_observe_nis), NaN: none */
  long mhold_k0;   /* hold_motor: its first tick, duration [s], offsets [n], [n] */
  double mhold_tb;
  int have_mhold;
  double *mhold_d0, *mhold_d1, *mr[3]; /* ...; control_motor_reference's outputs [n] x 3 */
  double *vt_prev; /* printed laws: v_t(k-1) */
  int have_vt;
  double *prev_qm_d, *prev_qmd_d; /* truth-ct: the previous motor set point and rate */
  long prev_k;
  int have_prev;
  /* scratch */
  double *x, *qmd_next, *Ksv, *o[8], *M, *b, *acc, *P;
};

/* amsfe_blend.c (control/blend.py), used by the controller's start-up (amsfe_ctrl.c) */
AMSFE_HIDDEN double blend_time(const double *d0, const double *d1, long n, double accel,
                               double rate);
AMSFE_HIDDEN double blend_through(const double *e0, const double *e1, long n, double wait,
                                  double accel, double rate, double *d0, double *d1);
AMSFE_HIDDEN void blend_offsets_into(double s, double tb, const double *d0, const double *d1,
                                     long n, int orders, double *out);
AMSFE_HIDDEN const double *blended(amsfe_ctrl *c, long k, const double *ref);
AMSFE_HIDDEN const double *blend_bandwidth(amsfe_ctrl *c, long k, const double *wf);

#endif /* AMSFE_LOOP_INTERNAL_H */

# %% [markdown]
# # Estimating a recording held as numpy arrays
#
# A notebook in jupytext's percent format: run it as a script (`python
# examples/estimate_arrays.py`) or open it as a notebook (`jupytext --to notebook`).
#
# The recording here is made by the simulator so that the truth is known; with your own arm
# the arrays come from wherever you keep them (a CSV, a driver's log, a data frame):
#
# - `t` [s]: the encoder sample times, on a grid of the robot's T (gaps allowed);
# - `q_motor` [rad], `qd_motor` [rad/s]: the motor encoders, one column per joint;
# - `effort` [N m]: the motor torque applied from each sample to the next;
# - `camera_t` [s], `camera_uv` [px], `camera_arrival_t` [s]: each camera frame's exposure
#   time, the tracked point's pixel and when the frame reached the computer.

# %%
import numpy as np

import amsfe_sym as am

sim = am.simulate("paper-sim", duration=2.0, seed=1)  # 2 s of the paper's 2-link arm
n = len(sim.joints)
T = sim.T
t = sim.t
q_motor = sim.run.z_enc[:, :n]  # what the simulated encoders read (noise, 2^17 counts/rev)
qd_motor = sim.run.z_enc[:, n:]
effort = sim.u
camera_t = sim.frames[:, 0] * T  # exposure step -> time
camera_arrival_t = sim.frames[:, 1] * T  # delivery step -> time
camera_uv = sim.frames[:, 2:4]
print(f"{t.size} samples of {n} joints, {camera_t.size} camera frames")

# %% [markdown]
# ## The recording as `LogArrays`, and the estimator over it
#
# `Estimator.for_scenario(scenario)` takes the filter of a scenario tuned for the arm (its
# `[filter]`, its `[estimate0]`, its sensors' noise as R): `amsfe estimate LOG --scenario
# FILE`.  `Estimator.for_log(robot)` is what `amsfe estimate LOG --robot ROBOT` runs for an
# arm with no scenario yet: the filter's defaults, started from the first sample.  `run`
# estimates the whole recording in one call of the compiled estimator.

# %%
log = am.LogArrays.from_arrays(
    t,
    q_motor,
    effort,
    camera_t,
    camera_uv,
    qd_motor=qd_motor,
    camera_arrival_t=camera_arrival_t,
)
est = am.Estimator.for_scenario("paper-sim").run(log)
print(f"frames fused: {est.counters['frames_applied']} of {camera_t.size}")

# %% [markdown]
# ## How close is it?
#
# The link angles' error over the last 80 % of the recording, against the simulator's
# truth, and the share of ticks where the error is inside the filter's own 2-sigma band.

# %%
last = slice(t.size // 5, None)
err = sim.q_true[last] - est.q_hat[last]
rmse_q = np.sqrt(np.mean(err**2, axis=0))
inside = np.mean(np.abs(err) <= 2 * est.q_std[last], axis=0)
print("link-angle RMSE [rad]:", np.round(rmse_q, 6).tolist())
print("inside 2 sigma:", np.round(inside, 3).tolist())
print(f"mean encoder NIS {np.nanmean(est.nis):.2f} (chi-square, {2 * n} degrees of freedom)")

# %% [markdown]
# ## Live: one sample at a time
#
# `step` takes each encoder sample as it arrives, `camera` each frame; the same estimator,
# the same numbers, for a loop that runs beside the arm.

# %%
live = am.Estimator.for_scenario("paper-sim")
frames_at = {}
for i, ta in enumerate(camera_arrival_t):
    frames_at.setdefault(round(ta / T), []).append(i)
for k in range(200):
    for i in frames_at.get(k, []):
        live.camera(camera_t[i], camera_uv[i])
    out = live.step(t[k], q_motor[k], effort[k], qd_motor=qd_motor[k])
print(f"after {out.k + 1} samples: q_hat = {np.round(out.q_hat, 4).tolist()} rad")
assert np.max(np.abs(out.x_hat - est.x_hat[out.k])) <= 1e-9  # the batch's estimate

"""Magnetometer calibration, ROS-free: online (causal, per sample, gyro-aided), offline (a whole recording) and
the saved file. Convention of the node (:mod:`riann_ros.magcal.input`): the field used is ``m = S (m_raw − h)``.

**Physics.** A field fixed in the world, seen from a sensor that turns by ``P`` (the bias-corrected gyro's rotation
between two readings), satisfies ``S (m₀ − h) = R(P) S (m₁ − h)``. With ``A = S`` and ``c = S h`` this is linear in
``(A, c)``; it observes ``h`` across every axis the sensor turns about (never along it), the soft iron where the
motion is rich, and not the common scale of ``(A, c)`` (the field's strength), which is fixed by the prior
(``⟨A, S_prior⟩ = |S_prior|²``; a heading does not depend on it).

**Online** (:class:`~.online.OnlineMagCalibrator`). Per sample, in plain floats: the gyro increment extends the open
window (one quaternion product) and the reading is calibrated with the current estimate. A window closes once the
sensor has turned 45°, or at the farthest reading of a swing that comes back before (or of 5 s) if that is at least
15° (less is dropped: no information), so nothing moves at rest or in straight motion. Per window, in numpy: its
innovation is gated (χ², 3 degrees of freedom, 99.9 %) against its noise (readings, the field's change along the
path, the gyro's bias residual, scale error and the latency fit's σ times the rate and the field) plus the
estimate's own uncertainty; a passing window is added to the information-form
least squares that started from the prior (the configured or saved calibration), keeping the data only in the
directions it knows at least as well as the prior, so a direction the motion does not observe stays at its prior
(the hard iron along a ground robot's vertical). Nothing is forgotten. Twenty consecutive rejected windows that agree
with one another replace the estimate (a magnet added or removed), or restore a rejected prior when they agree with
it. Soft-iron models: ``full`` (default: includes
the magnetometer's misalignment to the gyro, which the constraint observes; prior 1°), ``symmetric``, ``none``.

**What it knows.** The posterior covariance (scaled up by the variance of unit weight, with a systematic floor of
0.5 µT on the hard iron) gives, per sample, the σ it adds to a tilt-compensated heading for the current attitude and
field (:meth:`~.online.OnlineMagCalibrator.heading_sd_rad`). The state: *uncalibrated* (prior only), *converging*,
*calibrated* once the largest such σ over all headings at the current tilt is at most the field heading's own σ
(2.5°); the time it first was is kept.

**Offline** (:func:`~.offline.fit_recording`): all windows of a recording (one per reading), the same model, a robust
(Cauchy) least squares started from the online estimate, with a covariance; not the ``magyc`` package (why: module
docstring of :mod:`.offline`).

**The prior as a hypothesis** (:mod:`.hypothesis`): the configured (or saved) calibration is used as it is while
the windows are consistent with it (a calibrated sensor keeps its numbers), with the doubt they leave in the
heading's σ; once they reject it the estimate and its σ take over (docs/magnetometer.md, "Online calibration").

Modules: :mod:`.records` (frozen records and the physical constants), :mod:`.windows`, :mod:`.model`,
:mod:`.solver`, :mod:`.hypothesis`, :mod:`.online`, :mod:`.offline`, :mod:`.store` (the YAML file),
:mod:`.validate` (validation by physics of any calibration taken), :mod:`.synthetic` (test sensors).
"""

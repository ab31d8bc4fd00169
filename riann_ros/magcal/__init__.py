"""Magnetometer calibration, ROS-free: online (causal, per sample, gyro-aided), offline (a whole recording) and
the saved file.

* :mod:`.records` — the frozen records that cross the boundary (prior, estimate, status) and the physical constants;
* :mod:`.windows` — the per-sample part: windows of gyro rotation between two readings;
* :mod:`.model` — the linear constraint of one window, the prior, the covariances;
* :mod:`.online` — :class:`~.online.OnlineMagCalibrator`;
* :mod:`.offline` — :func:`~.offline.fit_recording` (robust batch least squares over all windows);
* :mod:`.store` — :func:`~.store.save_calibration` / :func:`~.store.load_calibration` (YAML, the node's names).
"""

"""Numerical core: pure numpy/scipy. Never imports rclpy, rosbags or matplotlib.

Grouped by stage, in the order the data flows (a stage imports only stages before it):

- :mod:`~pmsm_sysid.core.recording`: a recording of one axis and stamp alignment;
- :mod:`~pmsm_sysid.core.terms`: NARX terms, candidate sets, regressor matrices;
- :mod:`~pmsm_sysid.core.selection`: orthogonal forward regression (error reduction ratio),
  the checks before every fit, and ``identify`` from a recording to a validated model;
- :mod:`~pmsm_sysid.core.validation`: one-step-ahead and model predicted output, fit
  metrics, the five correlation tests;
- :mod:`~pmsm_sysid.core.frequency`: GFRFs H1-H3, ridges and poles;
- :mod:`~pmsm_sysid.core.physics`: plant files, excitation signals, the motor simulator
  (open loop or under a position loop);
- :mod:`~pmsm_sysid.core.plantfit`: a physical plant from a recording -- equation-error data,
  the library of named effects, their selection, estimation and held-out confirmation;
- :mod:`~pmsm_sysid.core.online`: windows, fit worker processes, the per-window tracker and
  change detection (what ``run`` does, without ROS);
- :mod:`~pmsm_sysid.core.discrepancy`: a recording against a plant -- ``diagnose``,
  sim-to-real: where the mismatch lives, what is left unexplained, the fit before/after;
- :mod:`~pmsm_sysid.core.fleet`: a fleet of axes -- the table of fitted plants (one row per
  recording axis) and each axis's parameters over time against its baseline, drift alarms.

Errors of every stage are the types in :mod:`~pmsm_sysid.core.errors`.
"""

"""Numerical core: pure numpy/scipy. Never imports rclpy, rosbags or matplotlib.

Grouped by stage, in the order the data flows (a stage imports only stages before it):

- :mod:`~pmsm_sysid.core.recording`: a recording of one axis and stamp alignment;
- :mod:`~pmsm_sysid.core.terms`: NARX terms, candidate sets, regressor matrices;
- :mod:`~pmsm_sysid.core.selection`: orthogonal forward regression (error reduction ratio),
  the checks before every fit, and ``identify`` from a recording to a validated model;
- :mod:`~pmsm_sysid.core.validation`: one-step-ahead and model predicted output, fit
  metrics, the five correlation tests;
- :mod:`~pmsm_sysid.core.frequency`: GFRFs H1-H3, ridges and poles;
- :mod:`~pmsm_sysid.core.physics`: plant files, excitation signals, the motor simulator;
- :mod:`~pmsm_sysid.core.online`: windows, fit worker processes, the per-window tracker and
  change detection (what ``run`` does, without ROS);
- :mod:`~pmsm_sysid.core.discrepancy`: ``diagnose``, sim-to-real.

Errors of every stage are the types in :mod:`~pmsm_sysid.core.errors`.
"""

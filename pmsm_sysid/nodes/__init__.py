"""Thin rclpy nodes: the simulated motor, the recorder, the replayer and the monitor.

Each ``__init__`` only wires parameters, publishers, subscriptions and timers; the work is
done by :mod:`pmsm_sysid.core` (physics, excitation, monitoring) and :mod:`pmsm_sysid.bagio`.
"""

"""The generated estimator and controller live on ROS 2 (docs/how-to/ros.md).

Modules: ``middleware`` (rclpy imported lazily, the environment it needs, QoS and stamps
from a :class:`~amsfe_sym.topics.TopicSpec`), ``arm`` (the simulated arm, tick by tick, as
:func:`amsfe_sym.sim.loop.run` builds and steps it), ``live`` (the estimator and controller
tick by tick on samples as they arrive, and the fail-safe hold), ``watchdog`` (when a node
holds and why: the reference of ``runtime/c/amsfe_watchdog.c``; docs/watchdogs.md),
``watchdog_runs`` (a free-running node and arm in process, with faults: what the watchdogs
are measured and tested on), ``record`` (what a node
received and published, as a rosbag2 in the layout of ``amsfe simulate --bag``),
``sim_node``, ``node`` and ``play`` (the rclpy nodes), ``lifecycle`` (``node --managed``),
``commands`` (their command-line options).

May import every room below the applications.  rclpy is imported only inside this room and
only when a node starts: ``amsfe --help`` works without the ``[ros]`` extra.
"""

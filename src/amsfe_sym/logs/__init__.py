"""Robot logs in and out: a run as a ROS 2 bag (rosbag2, MCAP storage) viewable in Foxglove,
and estimation on recorded rosbag2 / MCAP data (docs/logs.md).

Modules: ``spec`` (the log spec: topics, message types, joint names, grid tolerances),
``source`` (messages of a rosbag2 folder, MCAP or sqlite3 storage, or of a plain MCAP file,
without ROS), ``read`` (a log -> the estimator's inputs on its tick grid, with every skipped
message counted by reason), ``replay`` (a compiled estimator over a read log), ``write``
(a simulated run -> a rosbag2 in MCAP); ``decode`` and ``layout`` (a topic's payloads ->
columns, in bulk) and ``stream`` (a log's topics decoded in bounded memory: MCAP and ROS 1
bags chunk by chunk; docs/logs.md, "Speed").

May import: errors, core, load (the spec; Pinocchio only to draw ``/tf``), scenario, runtime,
estimation, sim (the run's result and its estimator builder).  Reading uses ``rosbags`` (and
``mcap`` for plain MCAP files); neither needs a ROS installation.
"""

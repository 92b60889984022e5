"""Robot logs in and out: a run as a ROS 2 bag (rosbag2, MCAP storage) viewable in Foxglove,
and estimation on recorded logs: ROS 1 ``.bag``, rosbag2 (MCAP or sqlite3), ``.mcap``
(docs/how-to/logs.md).

Modules: ``spec`` (the log spec is the topic spec of ``topics``), ``source`` (the payloads of
a log topic by topic, without ROS), ``decode`` and ``layout`` (a topic's payloads -> columns,
in bulk), ``stream`` (a log's topics decoded in bounded memory: MCAP and ROS 1 bags chunk by
chunk; docs/how-to/logs.md, "Speed"), ``chunks`` (an MCAP's chunks cut with numpy), ``firsts`` (the
first messages of a few topics, for the topic search), ``plan`` (which topic plays which
role, from the metadata and first messages), ``grid`` (the tick grid, the clock offset,
each role's usage), ``sensors`` (effort, camera frames and truth on the grid), ``read`` (a
log -> the estimator's inputs, every skipped message counted by reason), ``replay`` (an
estimator over a read log),
``write`` (a simulated run -> a rosbag2 in MCAP), ``bulk_write`` (many messages into
``rosbags``' MCAP writer at once), ``encode`` (JointState payloads in bulk).

May import: errors, core, load (the spec; Pinocchio only to draw ``/tf``), scenario, runtime,
estimation, sim (the run's result and its estimator builder), topics (the roles and the
topic spec).  Reading uses ``rosbags`` (and ``mcap`` for MCAP files: a plain one, or a
rosbag2 folder of one); neither needs a ROS installation.
"""

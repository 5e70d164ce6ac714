"""ROS 2, both directions: a bag → a robocal recording (`pipeline.ros2.importer.import_bag`), a
recording → a bag (`pipeline.ros2.export.export_bag`).  Bags are read and written with rosbags."""

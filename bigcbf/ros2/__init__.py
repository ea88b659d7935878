"""ROS 2 without a ROS install: DDS (the cyclonedds binding, ``pip install 'bigcbf[ros2]'``) with ROS 2's topic
names, type names, CDR and QoS; the twin as a ROS 2 robot (``bigcbf sim --ros2``) and the stack as a ROS 2 safety
filter node (``bigcbf filter --ros2``). docs/ros2.md describes it.

Robot side (:mod:`.filter_node` and what it imports) loads no simulator: no mujoco, dm_control or cv2.
"""

# SPDX-License-Identifier: Apache-2.0
"""
Model-validation workbench: measurement-data I/O (:mod:`.io`) and the tools built on it.

Nothing in this package imports rclpy; it runs on a machine without ROS.
"""

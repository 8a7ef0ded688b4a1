"""Eddie's base: board node, velocity control, twist mux, odometry, range sensors, safety,
robot description and state publishing.

Pure cores (``odometry``, ``kinematics``, ``twist_mux`` selection) sit beside thin nodes
(``*_node``) that map them onto topics, TF and parameters.
"""

__all__: list[str] = []

"""``two_robot_explore``: two sonar robots explore a pymunk world and merge their maps.

The manual is the docstring of :mod:`envs.two_robot_explore.env`; the versioned entry point is
:mod:`envs.two_robot_explore_v0`.
"""

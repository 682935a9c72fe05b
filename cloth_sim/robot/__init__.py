"""Robots in the scene: a URDF robot's links as colliders (:mod:`.robot`: loading, shapes, forward
kinematics through yourdfpy; :mod:`.resources`: ``package://`` look-up), placed in a simulation and
moved by joint positions (:mod:`.placement`). The ROS side (``robot_description``,
``/joint_states``) is in :mod:`cloth_sim.ros`."""

from .robot import Robot

__all__ = ["Robot"]

"""Dynamics models (Holonomic, HolonomicWithRotation, DiffDrive, KinematicBicycle)."""

"""Making vmas_ros stand in for VMAS 1.5 in code written for VMAS.

``install.py``: :func:`install_as_vmas` aliases the ``vmas`` package name to
vmas_ros. ``spaces.py``: :func:`~vmas_ros.compat.spaces.space_types`, the space
classes the Environment builds (legacy ``gym``'s while aliased, as VMAS does,
else gymnasium's). Importing this package imports neither torch nor gymnasium.
"""
from vmas_ros.compat.install import VMAS_VERSION, install_as_vmas, is_installed

__all__ = ["VMAS_VERSION", "install_as_vmas", "is_installed"]

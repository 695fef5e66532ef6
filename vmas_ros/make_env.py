"""VMAS's module path ``vmas.make_env``: the function lives in vmas_ros/envs/make_env.py.

Importing this module does not rebind ``vmas_ros.make_env`` to it: that name
stays the function (see ``_Package`` in vmas_ros/__init__.py), as in VMAS, whose
package re-exports the function under the module's own name.
"""
from vmas_ros.envs.make_env import make_env

__all__ = ["make_env"]

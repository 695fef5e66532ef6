"""vmas_ros's own release number, ``vmas_ros.__version__``.

It lives here, below every folder that reports it (benchmark results, exported
policies, ``install_as_vmas``'s ``vmas.vmas_ros_version``), so they need not
import the top-level package, which imports them. The VMAS release whose API
vmas_ros follows is :data:`vmas_ros.compat.install.VMAS_VERSION`.
"""

__version__ = "0.1.0"

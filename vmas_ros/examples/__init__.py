"""Runnable examples with VMAS's module paths and signatures (``python -m vmas_ros.examples.use_vmas_env``)."""

"""A trained policy in the engine and on robots that are not the engine, from the same start states.

``vmas-ros deploy-eval`` (:mod:`~vmas_ros.deploy.cli`) runs an exported
policy's episodes in the engine (:mod:`~vmas_ros.deploy.engine_side`), replays
their starts on ``robot_fleet`` through ``policy_node``
(:mod:`~vmas_ros.deploy.fleet_side`) and puts both side by side
(:mod:`~vmas_ros.deploy.report`). See docs/deploy.md.
"""

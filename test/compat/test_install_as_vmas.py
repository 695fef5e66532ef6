"""``vmas_ros.install_as_vmas()``: ``vmas`` resolves to vmas_ros's own modules, and the real VMAS stays unread.

Aliasing is process-wide and this test process has the real ``vmas`` imported
(the parity tests use it), so every check runs in a fresh interpreter.
"""
import os
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def run_python(code: str, tmp_path: Path) -> str:
    """Run ``code`` in a fresh interpreter (cwd ``tmp_path``, so no stray ``vmas`` beside it); its stdout."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], cwd=tmp_path, env=env,
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, f"subprocess failed:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def test_vmas_paths_are_the_vmas_ros_module_objects(tmp_path):
    run_python("""
        import sys
        import vmas_ros
        returned = vmas_ros.install_as_vmas()
        import vmas
        import vmas.simulator.core as core
        import vmas_ros.simulator.core
        from vmas.simulator.environment import Environment
        from vmas_ros.envs.environment import Environment as OurEnvironment

        assert returned is vmas and sys.modules["vmas"] is vmas
        assert core is vmas_ros.simulator.core and sys.modules["vmas.simulator.core"] is core
        assert vmas.simulator is vmas_ros.simulator and vmas.simulator.core is core
        # the module keeps its own identity: names, spec and file are vmas_ros's
        assert core.__name__ == "vmas_ros.simulator.core" and core.__spec__.name == "vmas_ros.simulator.core"
        assert Environment is OurEnvironment
        assert vmas.make_env is vmas_ros.make_env and vmas.scenarios == vmas_ros.scenarios
        env = vmas.make_env("navigation", num_envs=2)
        assert isinstance(env, Environment)
        # submodules imported through the alias are bound on vmas_ros, not copied onto `vmas`
        import vmas.envs
        assert "envs" not in vars(vmas) and vmas.envs is vmas_ros.envs
        assert "make_env" in dir(vmas)
    """, tmp_path)


def test_real_vmas_is_shadowed_and_never_read(tmp_path):
    out = run_python("""
        import importlib.machinery, os, sys
        spec = importlib.machinery.PathFinder.find_spec("vmas")  # the real one, located without importing it
        assert spec is not None and "vmas_ros" not in spec.origin, spec
        real_dir = os.path.dirname(spec.origin)
        touched = []

        def audit(event, args):
            if event in ("open", "os.listdir", "os.scandir") and args and isinstance(args[0], (str, bytes)):
                path = os.fsdecode(args[0])
                if os.path.abspath(path).startswith(real_dir + os.sep) or os.path.abspath(path) == real_dir:
                    touched.append((event, path))

        sys.addaudithook(audit)
        import vmas_ros
        vmas_ros.install_as_vmas()
        import vmas
        import vmas.simulator.core, vmas.simulator.utils, vmas.simulator.scenario, vmas.envs.environment
        env = vmas.make_env("simple_spread", num_envs=2)
        env.step(env.get_random_actions())
        loaded = sorted(name for name, m in sys.modules.items()
                        if (getattr(m, "__file__", None) or "").startswith(real_dir + os.sep))
        assert not touched, touched
        assert not loaded, loaded
        assert vmas.__file__ == vmas_ros.__file__
        print("real", real_dir)
    """, tmp_path)
    assert "real " in out


def test_refused_after_a_real_vmas_import(tmp_path):
    run_python("""
        import sys
        import vmas  # the real VMAS
        import vmas_ros
        try:
            vmas_ros.install_as_vmas()
        except RuntimeError as error:
            message = str(error)
        else:
            raise AssertionError("install_as_vmas() after `import vmas` did not raise")
        assert "before VMAS is imported" in message and "'vmas'" in message and vmas.__file__ in message, message
        assert sys.modules["vmas"] is vmas and vmas.__version__ == "1.5.2" and not hasattr(vmas, "vmas_ros_version")
        import vmas.simulator.core
        assert "vmas_ros" not in vmas.simulator.core.__file__  # nothing was aliased
    """, tmp_path)


def test_refused_after_torchrl_import(tmp_path):
    run_python("""
        import sys
        import torchrl
        import vmas_ros
        try:
            vmas_ros.install_as_vmas()
        except RuntimeError as error:
            message = str(error)
        else:
            raise AssertionError("install_as_vmas() after `import torchrl` did not raise")
        assert "before torchrl is imported" in message, message
        assert "vmas" not in sys.modules and not any(k.startswith("vmas.") for k in sys.modules)
    """, tmp_path)


def test_versions_idempotence_and_missing_paths(tmp_path):
    run_python("""
        import importlib, sys
        import vmas_ros
        from vmas_ros.compat import VMAS_VERSION
        first = vmas_ros.install_as_vmas()
        finders = [f for f in sys.meta_path if type(f).__name__ == "_AliasFinder"]
        assert vmas_ros.install_as_vmas() is first  # a second call is a no-op
        assert [f for f in sys.meta_path if type(f).__name__ == "_AliasFinder"] == finders and len(finders) == 1
        import vmas
        assert vmas.__version__ == VMAS_VERSION == "1.5.2", vmas.__version__
        assert vmas.vmas_ros_version == vmas_ros.__version__ != "1.5.2"
        # dropped from sys.modules, `vmas` comes back as the same alias, never the real package
        del sys.modules["vmas"]
        assert importlib.import_module("vmas") is first
        assert importlib.util.find_spec("vmas") is first.__spec__
        for missing, twin in (("vmas.nope", "vmas_ros.nope"), ("vmas.simulator.nope", "vmas_ros.simulator.nope")):
            try:
                importlib.import_module(missing)
            except ModuleNotFoundError as error:
                assert error.name == missing and repr(missing) in str(error) and repr(twin) in str(error), error
            else:
                raise AssertionError(f"import {missing} did not raise")
        try:
            vmas.nope
        except AttributeError as error:
            assert "'nope'" in str(error), error
        else:
            raise AssertionError("vmas.nope did not raise")
    """, tmp_path)


#: indented like the snippets it is joined to
SPACE_CHECK = """
        def space_kinds(**kwargs):
            env = vmas_ros.make_env("simple_speaker_listener", num_envs=2, **kwargs)
            spaces = [env.action_space, env.observation_space, env.get_agent_action_space(env.agents[0])]
            return [(type(s).__module__.split(".")[0], type(s).__name__) for s in spaces]
"""


def test_gym_spaces_only_while_installed(tmp_path):
    run_python("""
        import sys
        import vmas_ros
    """ + SPACE_CHECK + """
        assert space_kinds() == [("gymnasium", "Tuple"), ("gymnasium", "Tuple"), ("gymnasium", "Box")], space_kinds()
        assert "gym" not in sys.modules  # without the alias, legacy gym is never imported
        vmas_ros.install_as_vmas()
        assert space_kinds() == [("gym", "Tuple"), ("gym", "Tuple"), ("gym", "Box")], space_kinds()
        assert space_kinds(continuous_actions=False)[2] == ("gym", "Discrete")
        assert space_kinds(continuous_actions=False, multidiscrete_actions=True)[2] == ("gym", "MultiDiscrete")
        assert space_kinds(dict_spaces=True)[:2] == [("gym", "Dict"), ("gym", "Dict")]
        import gym
        env = vmas_ros.make_env("navigation", num_envs=1, continuous_actions=False)
        assert env.action_space == gym.spaces.Tuple([gym.spaces.Discrete(9)] * env.n_agents), env.action_space
    """, tmp_path)


def test_without_legacy_gym_it_warns_and_keeps_gymnasium_spaces(tmp_path):
    run_python("""
        import sys, warnings
        sys.modules["gym"] = None  # how Python marks a package as not importable
        import vmas_ros
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            vmas_ros.install_as_vmas()
        assert any("vmas_ros[gym]" in str(w.message) and w.category is RuntimeWarning for w in caught), caught
    """ + SPACE_CHECK + """
        assert space_kinds() == [("gymnasium", "Tuple"), ("gymnasium", "Tuple"), ("gymnasium", "Box")], space_kinds()
    """, tmp_path)


SPAWN_SCRIPT = '''
import vmas_ros
vmas_ros.install_as_vmas()  # at the top, outside the main guard: spawned workers run it too
import multiprocessing


def worker(queue):
    import vmas
    queue.put((vmas.vmas_ros_version, type(vmas.make_env("simple", num_envs=1)).__module__))


if __name__ == "__main__":
    context = multiprocessing.get_context("spawn")
    queue = context.Queue()
    process = context.Process(target=worker, args=(queue,))
    process.start()
    print(queue.get(timeout=60))
    process.join()
'''


def test_spawned_workers_get_the_alias_from_the_main_script(tmp_path):
    script = tmp_path / "train.py"
    script.write_text(SPAWN_SCRIPT)
    out = run_python(f"import runpy; runpy.run_path({str(script)!r}, run_name='__main__')", tmp_path)
    import vmas_ros

    assert out.strip() == str((vmas_ros.__version__, "vmas_ros.envs.environment")), out

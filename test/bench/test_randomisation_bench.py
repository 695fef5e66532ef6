"""`vmas-ros bench randomisation`: every configuration timed against randomisation off, written out."""
import json

from vmas_ros.bench.randomisation_bench import CONFIGURATIONS, format_table
from vmas_ros.cli import main


def test_each_configuration_is_timed_against_randomisation_off(tmp_path, capsys):
    argv = ["bench", "randomisation", "--randomisation-envs", "8", "--randomisation-modes", "eager", "--steps", "5",
            "--repeats", "2", "--no-progress", "--out", str(tmp_path)]
    assert main(argv) == 0
    rows = json.loads((tmp_path / "randomisation.json").read_text())
    assert [row["configuration"] for row in rows] == list(CONFIGURATIONS)
    assert all(row["mode"] == "eager" and len(row["samples_ms"]) == 2 and row["ms_per_step"] > 0 for row in rows)
    assert rows[0]["cost"] == 0 and (tmp_path / "randomisation.md").is_file()
    assert "| eager | all | 8 |" in capsys.readouterr().out


def test_the_table_marks_the_goal():
    rows = [{"mode": "compiled", "configuration": name, "num_envs": 600, "ms_per_step": 1.0 + cost, "cost": cost}
            for name, cost in (("off", 0.0), ("commands", 0.05), ("all", 0.2))]
    table = format_table(rows)
    assert "+5.0% | ✓ < 10%" in table and "+20.0% | ✗ < 10%" in table


def test_bad_options_are_refused(capsys):
    assert main(["bench", "randomisation", "--randomisation-modes", "fast", "--no-progress"]) == 2
    assert "modes must be among ['eager', 'compiled']" in capsys.readouterr().err

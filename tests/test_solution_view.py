"""The notebook layer's view of reference solutions: shown only on request, passing reports real."""

from __future__ import annotations

import pytest

from course_helpers import CourseError
from course_helpers.checks.ch04_services import check_battery_server
from course_helpers.notebook.solution import show_passing_report, solution_source


def test_solution_source_is_the_reference_code_and_bad_names_say_what_is_allowed():
    code = solution_source("ch04_services", "BatteryMonitor")
    assert code.startswith("class BatteryMonitor(")
    with pytest.raises(CourseError, match="has no 'Nope'"):
        solution_source("ch04_services", "Nope")
    with pytest.raises(CourseError, match="name a solution like"):
        solution_source("ch04 services", "BatteryMonitor")
    with pytest.raises(CourseError, match="not part of this copy"):
        solution_source("ch99_missing", "Anything")


def test_the_passing_report_runs_the_reference_against_real_nodes(rt, capsys):
    report = show_passing_report(lambda cls: check_battery_server(cls, rt), "ch04_services", "BatteryMonitor")
    assert report is not None and report.passed, report.summary()
    shown = capsys.readouterr().out
    # outside a kernel IPython prints the text form: a record of the real report, no solution code
    assert "what passing looks like" in shown and "PASSED" in shown
    assert "class BatteryMonitor" not in shown


def test_a_reference_that_fails_its_checker_is_an_error_not_a_passing_report(rt, capsys):
    from course_helpers.checks import CheckReport

    def failing(cls):
        report = CheckReport("Battery server")
        report.add("answers every request", False, "2 of 3 answered")
        return report

    with pytest.raises(CourseError, match="did not pass its own checker"):
        show_passing_report(failing, "ch04_services", "BatteryMonitor")
    assert "what passing looks like" not in capsys.readouterr().out


def test_without_solutions_the_passing_report_says_why(capsys):
    assert show_passing_report(lambda cls: None, "ch99_missing", "Anything") is None
    assert "not available here" in capsys.readouterr().out


def test_a_solution_that_is_a_value_is_refused_with_a_reason():
    with pytest.raises(CourseError, match="is a value, not a function or class"):
        solution_source("ch04_services", "__name__")


def test_running_the_passing_report_again_shows_the_report_the_kernel_measured(capsys):
    from course_helpers.checks import CheckReport

    runs = []

    def counting(cls):  # a check that costs nothing, so that the test can count its runs
        runs.append(cls.__name__)
        report = CheckReport("Battery server")
        report.add("answers every request", True, f"run {len(runs)}")
        return report

    first = show_passing_report(counting, "ch04_services", "BatteryMonitor")
    assert runs == ["BatteryMonitor"] and "shown again" not in capsys.readouterr().out
    again = show_passing_report(counting, "ch04_services", "BatteryMonitor")
    shown = capsys.readouterr().out
    assert again is first and runs == ["BatteryMonitor"]  # not run a second time
    assert "run 1" in shown and "checked in this kernel at" in shown and "shown again" in shown
    anew = show_passing_report(counting, "ch04_services", "BatteryMonitor", recheck=True)
    assert len(runs) == 2 and anew is not first and "run 2" in capsys.readouterr().out

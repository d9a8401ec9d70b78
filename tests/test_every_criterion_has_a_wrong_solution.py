"""Every criterion of every exercise checker has a wrong solution that fails it (issue 32, item 7).

The checkers are found by introspection: every ``check_*`` function defined in a module of
``course_helpers/checks/``, so a new checker cannot be forgotten. What each one reports for its
reference solution is recorded in ``tests/data/reference_criteria.json`` (kept true by the
reference tests, :mod:`tests.criteria_registry`), and the criteria a checker adds only when they fail
are listed by hand in ``ONLY_WHEN_FAILING`` beside their tests; what the wrong solutions fail is what
the test modules declare in ``COVERED``, and what none can fail, with the reason, in ``EXEMPT``. No
ROS runs here: this test reads the record and the declarations.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import course_helpers.checks as checks_package

from .criteria_registry import declarations, gaps, read_record


def checkers() -> dict[str, str]:
    """Every exercise checker: the name of each ``check_*`` function of ``course_helpers.checks``'s
    modules -> its module (a name must be unique: the record is keyed by it)."""
    found: dict[str, str] = {}
    for info in pkgutil.iter_modules(checks_package.__path__):
        module = importlib.import_module(f"{checks_package.__name__}.{info.name}")
        for name, function in inspect.getmembers(module, inspect.isfunction):
            if name.startswith("check_") and function.__module__ == module.__name__:
                assert name not in found, f"two checkers are called {name}: {found[name]}, {module.__name__}"
                found[name] = module.__name__
    return found


def test_every_criterion_of_every_checker_has_a_wrong_solution_that_fails_it():
    covered, exempt, only_when_failing = declarations()
    problems = gaps(checkers(), read_record(), covered, exempt, only_when_failing)
    assert not problems, ("criteria that no wrong solution fails (checker: criterion), and other gaps:\n  "
                          + "\n  ".join(problems))


def test_the_checkers_are_found_by_introspection_in_their_modules():
    found = checkers()
    assert {"check_environment", "check_private_robot", "check_package", "check_heartbeat",
            "check_burst_qos", "check_fleet_estop"} <= set(found)
    assert found["check_heartbeat"] == "course_helpers.checks.ch08_qos_events"


def test_a_gap_is_named_for_each_way_the_claim_can_break():
    record = {"check_a": ["one", "two", "three"], "check_gone": ["x"]}
    covered = {"check_a": {"one"}, "check_typo": {"one"}}
    exempt = {"check_a": {"two": "reported only on a machine without namespaces", "four": "stale"},
              "check_b": {}}
    assert gaps(["check_a", "check_b"], record, covered, exempt) == [
        "check_a: three",
        "check_b: no entry in tests/data/reference_criteria.json (its reference test must call "
        "assert_reference_criteria)",
        "check_gone: recorded, but no checker of that name exists",
        "check_typo: a test module declares wrong solutions for it, but no checker of that name exists",
        "check_a: exempts 'four', which its reference report does not hold and no module lists as reported "
        "only when it fails",
    ]
    assert gaps(["check_a"], {"check_a": ["one"]}, {}, {"check_a": {"one": " "}}) == [
        "check_a: exempts 'one' without a reason"]
    assert gaps(["check_a"], {"check_a": ["one"]}, {"check_a": {"one"}}, {}) == []


def test_criteria_reported_only_when_failing_need_a_wrong_solution_too():
    record = {"check_a": ["one"]}
    only = {"check_a": {"the node can be created", "not tried", "one"}}
    covered = {"check_a": {"one", "the node can be created"}}
    exempt = {"check_a": {"not tried": "the checker's own nodes"}}
    assert gaps(["check_a"], record, covered, exempt, only) == [
        "check_a: 'one' is listed as reported only when it fails, but the reference's report holds it"]
    assert gaps(["check_a"], record, {"check_a": {"one"}}, {}, {"check_a": {"not tried"}}) == [
        "check_a: not tried"]

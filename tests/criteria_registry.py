"""What every exercise checker reports for its reference solution, and which wrong solutions fail it.

``tests/data/reference_criteria.json`` records, for each checker (the ``check_*`` function's name), the
names of the criteria its report holds for the reference solution, in the report's order. Every test
that runs a checker on its reference solution passes the report to :func:`assert_reference_criteria`,
so the record stays what the checker really reports. ``tests/test_every_criterion_has_a_wrong_solution.py``
then compares the record with what the test modules declare at module level:

* ``COVERED = {"check_name": {criterion, ...}}``: the criteria a wrong solution of that module fails,
  built from the very tables its tests assert on (a name is there only if a test sees it fail);
* ``EXEMPT = {"check_name": {criterion: "why no wrong solution fails it in a test"}}``;
* ``ONLY_WHEN_FAILING = {"check_name": {criterion, ...}}``: criteria the checker adds only when they
  fail ("the node can be created", "not tried: ..."), which the reference's report therefore does not
  hold. No run can list them, so they are listed by hand, beside the tests of their checker; once
  listed, each needs a wrong solution or an exemption like any other.

Reading the record and the declarations runs no ROS: the central test takes a second.
"""

from __future__ import annotations

import ast
import fcntl
import importlib
import json
import os
from pathlib import Path

TESTS = Path(__file__).resolve().parent
RECORD = TESTS / "data" / "reference_criteria.json"
UPDATE_ENV = "COURSE_UPDATE_REFERENCE_CRITERIA"  # =1: a reference test rewrites its entry instead of failing
DECLARATIONS = ("COVERED", "EXEMPT", "ONLY_WHEN_FAILING")


def read_record() -> dict[str, list[str]]:
    """checker name -> the names of its reference report's criteria ({} if there is no record yet)."""
    if not RECORD.exists():
        return {}
    return json.loads(RECORD.read_text())


def _names(report_or_names) -> list[str]:
    names = ([c.name for c in report_or_names.criteria] if hasattr(report_or_names, "criteria")
             else list(report_or_names))
    return list(dict.fromkeys(names))  # in order, each once


def assert_reference_criteria(checker: str, report_or_names) -> None:
    """The criteria of ``checker``'s report on the reference solution (a CheckReport, or their names) are
    the ones the record lists for it. With ``COURSE_UPDATE_REFERENCE_CRITERIA=1`` the record's entry is
    rewritten instead (commit the file, then give each new criterion a wrong solution)."""
    names = _names(report_or_names)
    recorded = read_record().get(checker)
    if names == recorded:
        return
    if os.environ.get(UPDATE_ENV) == "1":
        _write_entry(checker, names)
        return
    added = [n for n in names if n not in (recorded or [])]
    gone = [n for n in (recorded or []) if n not in names]
    lines = [f"{checker}'s reference report no longer matches {RECORD.relative_to(TESTS.parent)}"
             if recorded is not None else f"{checker} has no entry in {RECORD.relative_to(TESTS.parent)}"]
    lines += [f"  + {n}" for n in added] + [f"  - {n}" for n in gone]
    if not added and not gone:
        lines.append("  (the same names in another order)")
    lines.append(f"If the checker changed on purpose, run this test again with {UPDATE_ENV}=1 (it rewrites "
                 "the entry), commit the file, and give every new criterion a wrong solution that fails it "
                 "(the test module's COVERED) or a reason why none can (its EXEMPT).")
    raise AssertionError("\n".join(lines))


def _write_entry(checker: str, names: list[str]) -> None:
    """Rewrite one entry of the record; parallel test workers take turns (a lock on the file)."""
    RECORD.parent.mkdir(parents=True, exist_ok=True)
    with open(RECORD, "a+", encoding="utf-8") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        handle.seek(0)
        text = handle.read()
        record = json.loads(text) if text.strip() else {}
        record[checker] = names
        handle.seek(0)
        handle.truncate()
        handle.write(json.dumps(dict(sorted(record.items())), indent=1, ensure_ascii=False) + "\n")


def failing(table, position: int = 1) -> set[str]:
    """The union of the criterion sets at ``position`` of a table of ``pytest.param(...)`` rows."""
    return set().union(*(row.values[position] for row in table))


def recorded_names_starting_with(checker: str, prefixes) -> set[str]:
    """The recorded criteria of ``checker`` that start with one of ``prefixes`` (for tests that name a
    criterion by its start, as chapter 00's does for names holding a version)."""
    return {name for name in read_record().get(checker, []) if name.startswith(tuple(prefixes))}


def declaring_modules() -> list[str]:
    """The test modules that set COVERED or EXEMPT at module level (found by parsing, not importing)."""
    found = []
    for path in sorted(TESTS.glob("test_*.py")):
        tree = ast.parse(path.read_text(), str(path))
        targets = {t.id for node in tree.body if isinstance(node, (ast.Assign, ast.AnnAssign))
                   for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
                   if isinstance(t, ast.Name)}
        if targets & set(DECLARATIONS):
            found.append(f"tests.{path.stem}")
    return found


def declarations() -> tuple[dict[str, set[str]], dict[str, dict[str, str]], dict[str, set[str]]]:
    """(covered, exempt, only_when_failing): every test module's COVERED, EXEMPT and ONLY_WHEN_FAILING,
    merged by checker."""
    covered: dict[str, set[str]] = {}
    exempt: dict[str, dict[str, str]] = {}
    only_when_failing: dict[str, set[str]] = {}
    for name in declaring_modules():
        module = importlib.import_module(name)
        for checker, criteria in getattr(module, "COVERED", {}).items():
            covered.setdefault(checker, set()).update(criteria)
        for checker, reasons in getattr(module, "EXEMPT", {}).items():
            exempt.setdefault(checker, {}).update(reasons)
        for checker, criteria in getattr(module, "ONLY_WHEN_FAILING", {}).items():
            only_when_failing.setdefault(checker, set()).update(criteria)
    return covered, exempt, only_when_failing


def gaps(checkers, record: dict[str, list[str]], covered: dict[str, set[str]],
         exempt: dict[str, dict[str, str]],
         only_when_failing: dict[str, set[str]] | None = None) -> list[str]:
    """What keeps "every criterion of every checker has a wrong solution that fails it" from being true,
    one line each: a checker without a record; a criterion (recorded, or listed as reported only when
    it fails) that no wrong solution fails and no exemption explains; a criterion listed as reported
    only when failing that the reference reports; an exemption of something that is neither; a
    declaration about a checker that does not exist; an exemption without a reason."""
    only_when_failing = only_when_failing or {}
    problems = []
    for checker in sorted(checkers):
        if checker not in record:
            problems.append(f"{checker}: no entry in tests/data/reference_criteria.json (its reference test "
                            "must call assert_reference_criteria)")
            continue
        failing_only = sorted(only_when_failing.get(checker, set()))
        for criterion in [*record[checker], *failing_only]:
            if criterion not in covered.get(checker, set()) and criterion not in exempt.get(checker, {}):
                problems.append(f"{checker}: {criterion}")
        for criterion in failing_only:
            if criterion in record[checker]:
                problems.append(f"{checker}: {criterion!r} is listed as reported only when it fails, but the "
                                "reference's report holds it")
    for checker in sorted(set(record) - set(checkers)):
        problems.append(f"{checker}: recorded, but no checker of that name exists")
    for checker in sorted((set(covered) | set(exempt) | set(only_when_failing)) - set(checkers)):
        problems.append(f"{checker}: a test module declares wrong solutions for it, but no checker of that "
                        "name exists")
    for checker, reasons in sorted(exempt.items()):
        for criterion, why in sorted(reasons.items()):
            known = [*record.get(checker, []), *only_when_failing.get(checker, ())]
            if criterion not in known:
                problems.append(f"{checker}: exempts {criterion!r}, which its reference report does not hold "
                                "and no module lists as reported only when it fails")
            elif not str(why).strip():
                problems.append(f"{checker}: exempts {criterion!r} without a reason")
    return problems

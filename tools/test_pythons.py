"""Set the course up from scratch and test it on every supported Python (3.10-3.13) found here.

For each version, the interpreter is taken from the environment variable ``PYTHON310``,
``PYTHON311``, ``PYTHON312`` or ``PYTHON313`` when it is set, otherwise from ``python3.10`` ...
``python3.13`` on PATH; a version with neither is reported as SKIPPED. Each found interpreter gets
a fresh ``git clone`` of this repository's committed HEAD (uncommitted changes are *not* tested) in
a temporary directory, where the script runs

    make setup PYTHON=<interpreter> VENV=<temporary venv>
    <venv>/bin/python -m pytest <pytest args>

and then prints one line per version: version, set-up seconds, test seconds, PASS/FAIL/SKIPPED.
Progress (which version, which step, the commands' own output) is streamed as it happens.

Usage::

    python3 tools/test_pythons.py                       # all versions, strict nbval of all notebooks
    python3 tools/test_pythons.py --pythons 3.10,3.13   # only these versions
    python3 tools/test_pythons.py --pytest-args "tests -q"
    PYTHON312=/opt/py312/bin/python3 python3 tools/test_pythons.py

Exit status: 0 when every found interpreter passed, 1 when any failed, 2 for bad options or when
no interpreter was found at all. Only the standard library is used, so any Python 3.8+ runs it.
"""

from __future__ import annotations

import argparse
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

VERSIONS = ("3.10", "3.11", "3.12", "3.13")
# Mirrors `make notebooks`: strict nbval of every notebook (then each once more in the same kernel),
# with the Makefile's workers and timeouts.
DEFAULT_PYTEST_ARGS = (
    "--nbval --nbval-current-env --nbval-sanitize-with tests/nbval_sanitize.cfg "
    "--nbval-cell-timeout=120 -p no:cacheprovider -n 5 --dist loadfile --no-loadscope-reorder notebooks -q"
)
DEFAULT_TIMEOUT_S = 3600.0  # per step (set-up, tests) and version
HEARTBEAT_S = 30.0  # a silent step prints "still running" this often
REPO_ROOT = Path(__file__).resolve().parents[1]
# Variables that would make the clone's make or venv use something else than the clone's own files.
SCRUBBED_ENV = ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "MAKEFLAGS", "MFLAGS", "MAKELEVEL")


@dataclass
class Result:
    version: str  # "3.10"
    status: str = "SKIPPED"  # PASS, FAIL or SKIPPED
    interpreter: str = ""
    full_version: str = ""  # "3.10.13", as the interpreter reports it
    setup_s: float | None = None
    test_s: float | None = None
    reason: str = ""  # why it failed or was skipped


def say(message: str) -> None:
    print(f"[test_pythons] {message}", flush=True)


def env_var(version: str) -> str:
    return "PYTHON" + version.replace(".", "")


def find_interpreter(version: str) -> tuple[str | None, str]:
    """Return (interpreter path or None, where it came from or why it is missing)."""
    var = env_var(version)
    value = os.environ.get(var, "").strip()
    if value:
        path = shutil.which(value)  # a bare name is looked up on PATH, a path is checked as is
        if path is None:
            return None, f"{var}={value!r} is not an executable file"
        return path, f"from {var}"
    path = shutil.which(f"python{version}")
    if path is None:
        return None, f"not found ({var} is unset and python{version} is not on PATH)"
    return path, "from PATH"


def interpreter_version(path: str) -> str:
    """The interpreter's X.Y.Z, or raise RuntimeError saying why it cannot be asked."""
    try:
        out = subprocess.run(
            [path, "-c", "import platform; print(platform.python_version())"],
            capture_output=True, text=True, timeout=60, check=False,
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise RuntimeError(f"cannot run {path}: {exc}") from exc
    if out.returncode != 0:
        raise RuntimeError(f"{path} exited with {out.returncode}: {out.stderr.strip()[-300:]}")
    return out.stdout.strip()


class StepFailed(Exception):
    pass


def run_step(label: str, cmd: list[str], cwd: Path, env: dict[str, str], log_path: Path,
             timeout_s: float) -> float:
    """Run ``cmd``, streaming its output prefixed with ``label`` and into ``log_path``.

    Returns the seconds it took; raises StepFailed on a non-zero exit or a time-out.
    """
    say(f"{label}: $ {shlex.join(cmd)}")
    start = time.monotonic()
    # Shared with the reader thread: when output last came, and whether the terminal is mid-line.
    state = {"last_output": start, "at_line_start": True}
    with open(log_path, "wb") as log:
        log.write(f"$ {shlex.join(cmd)}\n(cwd {cwd})\n".encode())
        log.flush()
        try:
            proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    start_new_session=True)
        except OSError as exc:
            raise StepFailed(f"cannot start {cmd[0]}: {exc}") from exc

        def pump() -> None:
            # Read in chunks, not lines: pytest -q prints its dots without a newline.
            assert proc.stdout is not None
            while True:
                chunk = os.read(proc.stdout.fileno(), 4096)
                if not chunk:
                    break
                log.write(chunk)
                log.flush()
                state["last_output"] = time.monotonic()
                text = chunk.decode(errors="replace")
                pieces = []
                for line in text.splitlines(keepends=True):
                    pieces.append(f"  [{label}] {line}" if state["at_line_start"] else line)
                    state["at_line_start"] = line.endswith("\n")
                sys.stdout.write("".join(pieces))
                sys.stdout.flush()
            if not state["at_line_start"]:
                sys.stdout.write("\n")
                sys.stdout.flush()
                state["at_line_start"] = True

        reader = threading.Thread(target=pump, daemon=True)
        reader.start()
        timed_out = False
        try:
            while proc.poll() is None:
                now = time.monotonic()
                if now - start > timeout_s:
                    timed_out = True
                    stop_group(proc)
                    break
                if now - state["last_output"] >= HEARTBEAT_S:
                    if not state["at_line_start"]:  # e.g. in the middle of pytest's dots
                        print(flush=True)
                        state["at_line_start"] = True
                    say(f"{label}: still running ({now - start:.0f} s) ...")
                    state["last_output"] = now
                time.sleep(0.5)
        except KeyboardInterrupt:
            stop_group(proc)
            raise
        proc.wait()
        reader.join(timeout=10)
    seconds = time.monotonic() - start
    if timed_out:
        raise StepFailed(f"{label} did not finish in {timeout_s:.0f} s and was stopped (log: {log_path})")
    if proc.returncode != 0:
        raise StepFailed(f"{label} exited with {proc.returncode} after {seconds:.0f} s (log: {log_path})")
    say(f"{label}: done in {seconds:.1f} s")
    return seconds


def stop_group(proc: subprocess.Popen) -> None:
    """Stop the process group this script started for one step (its own session)."""
    for sig, grace in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=grace)
            return
        except subprocess.TimeoutExpired:
            continue


def check_version(version: str, repo: Path, work: Path, pytest_args: list[str], timeout_s: float,
             keep: bool) -> Result:
    result = Result(version)
    say(f"=== Python {version} ===")
    path, origin = find_interpreter(version)
    if path is None:
        result.reason = origin
        if not origin.startswith("not found"):  # an env var names a missing interpreter: a mistake
            result.status = "FAIL"
        say(f"{version}: {result.status}, {origin}")
        return result
    result.interpreter = path
    try:
        result.full_version = interpreter_version(path)
    except RuntimeError as exc:
        result.status, result.reason = "FAIL", str(exc)
        say(f"{version}: FAIL, {exc}")
        return result
    if not result.full_version.startswith(version + "."):
        result.status = "FAIL"
        result.reason = f"{path} ({origin}) is Python {result.full_version}, not {version}"
        say(f"{version}: FAIL, {result.reason}")
        return result
    say(f"{version}: using {path} ({origin}), Python {result.full_version}")

    base = work / f"py{version.replace('.', '')}"
    clone, venv = base / "course", base / "venv"
    base.mkdir(parents=True)
    env = {k: v for k, v in os.environ.items() if k not in SCRUBBED_ENV}
    env["PYTHONUNBUFFERED"] = "1"
    step = "clone"
    try:
        run_step(f"{version} clone", ["git", "clone", "-q", str(repo), str(clone)], work, env,
                 base / "clone.log", timeout_s)
        step = "set-up"
        result.setup_s = run_step(
            f"{version} setup", ["make", "setup", f"PYTHON={path}", f"VENV={venv}"], clone, env,
            base / "setup.log", timeout_s)
        step = "tests"
        result.test_s = run_step(
            f"{version} tests", [str(venv / "bin" / "python"), "-m", "pytest", *pytest_args], clone,
            env, base / "tests.log", timeout_s)
        result.status = "PASS"
    except StepFailed as exc:
        result.status, result.reason = "FAIL", f"{step}: {exc}"
        say(f"{version}: FAIL in {step}: {exc}")
    finally:
        if not keep:
            # The clone and venv take about a gigabyte; the logs stay until the end.
            shutil.rmtree(clone, ignore_errors=True)
            shutil.rmtree(venv, ignore_errors=True)
    if result.status == "PASS":
        say(f"{version}: PASS")
    return result


def fmt_seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.0f}"


def print_summary(results: list[Result]) -> None:
    print("\n[test_pythons] summary", flush=True)
    header = f"{'python':<8} {'version':<9} {'setup s':>8} {'tests s':>8}  result"
    print(header)
    print("-" * len(header))
    for r in results:
        status = "SKIPPED (not found)" if r.status == "SKIPPED" else r.status
        print(f"{r.version:<8} {r.full_version or '-':<9} {fmt_seconds(r.setup_s):>8} "
              f"{fmt_seconds(r.test_s):>8}  {status}")
    for r in results:
        if r.status == "FAIL":
            print(f"  {r.version}: {r.reason}")
    sys.stdout.flush()


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="tools/test_pythons.py",
        description="Fresh clone, `make setup` and tests on every supported Python found "
                    "(PYTHON310..PYTHON313 env vars, else python3.10..python3.13 on PATH).",
        epilog="Exit status: 0 all found interpreters passed, 1 one failed, 2 bad options or none found.",
    )
    parser.add_argument("--pythons", default=",".join(VERSIONS), metavar="X.Y[,X.Y...]",
                        help=f"versions to test, comma-separated (default: {','.join(VERSIONS)})")
    parser.add_argument("--pytest-args", default=DEFAULT_PYTEST_ARGS, metavar="ARGS",
                        help="arguments for `python -m pytest`, run in the clone, as one quoted string "
                             f"(default, the Makefile's strict nbval: {DEFAULT_PYTEST_ARGS!r})")
    parser.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT_S, metavar="SECONDS",
                        help=f"limit for each step of each version (default: {DEFAULT_TIMEOUT_S:.0f})")
    parser.add_argument("--repo", type=Path, default=REPO_ROOT, metavar="DIR",
                        help="repository whose committed HEAD is cloned (default: this one)")
    parser.add_argument("--workdir", type=Path, default=None, metavar="DIR",
                        help="where the temporary clones go (default: the system's temporary directory)")
    parser.add_argument("--keep", action="store_true",
                        help="keep the clones and venvs (about 1 GB each) instead of deleting them")
    # `--pytest-args -q` would read -q as an option of this script: take the next word as the value.
    argv = list(argv)
    for i, arg in enumerate(argv[:-1]):
        if arg == "--pytest-args":
            argv[i : i + 2] = [f"--pytest-args={argv[i + 1]}"]
            break
    args = parser.parse_args(argv)

    wanted = [v.strip() for v in args.pythons.split(",") if v.strip()]
    unknown = [v for v in wanted if v not in VERSIONS]
    if unknown or not wanted:
        parser.error(f"--pythons: {', '.join(unknown) or 'nothing given'} is not a supported version; "
                     f"choose among {', '.join(VERSIONS)} (e.g. --pythons 3.10,3.12)")
    args.versions = [v for v in VERSIONS if v in wanted]
    try:
        args.pytest_list = shlex.split(args.pytest_args)
    except ValueError as exc:
        parser.error(f"--pytest-args cannot be split like a shell command line ({exc}): {args.pytest_args!r}")
    if not args.pytest_list:
        parser.error("--pytest-args is empty; give at least a path, e.g. --pytest-args 'tests -q'")
    if not args.timeout > 0:
        parser.error(f"--timeout must be a positive number of seconds, not {args.timeout:g}")
    for tool in ("git", "make"):
        if shutil.which(tool) is None:
            parser.error(f"`{tool}` is not on PATH; this script needs git and make")
    repo = args.repo.resolve()
    top = subprocess.run(["git", "-C", str(repo), "rev-parse", "--show-toplevel"],
                         capture_output=True, text=True, check=False)
    if top.returncode != 0:
        parser.error(f"--repo: {repo} is not a git repository ({top.stderr.strip()})")
    args.repo = Path(top.stdout.strip())
    if not (args.repo / "Makefile").is_file():
        parser.error(f"--repo: {args.repo} has no Makefile; point --repo at the course repository")
    if args.workdir is not None:
        if not args.workdir.is_dir():
            parser.error(f"--workdir: {args.workdir} is not an existing directory")
        args.workdir = args.workdir.resolve()
    return args


def main(argv: list[str]) -> int:
    args = parse_args(argv)
    dirty = subprocess.run(["git", "-C", str(args.repo), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True, check=False).stdout.strip()
    head = subprocess.run(["git", "-C", str(args.repo), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True, check=False).stdout.strip()
    say(f"testing committed HEAD {head} of {args.repo} on Python {', '.join(args.versions)}")
    if dirty:
        say("note: the work tree has uncommitted changes; they are NOT tested (only HEAD is cloned)")
    say(f"tests: python -m pytest {shlex.join(args.pytest_list)}")

    work = Path(tempfile.mkdtemp(prefix="course-pythons-", dir=args.workdir))
    say(f"working in {work}")
    results: list[Result] = []
    try:
        for version in args.versions:
            results.append(check_version(version, args.repo, work, args.pytest_list, args.timeout, args.keep))
    except KeyboardInterrupt:
        say(f"interrupted; logs and anything not yet removed are in {work}")
        return 130
    print_summary(results)

    failed = [r for r in results if r.status == "FAIL"]
    found = [r for r in results if r.status != "SKIPPED"]
    if failed or args.keep:
        say(f"logs{' and clones' if args.keep else ''} kept in {work}")
    else:
        shutil.rmtree(work, ignore_errors=True)
    if not found:
        say("no interpreter was found, nothing was tested: put python3.10 ... python3.13 on PATH "
            "or set PYTHON310 ... PYTHON313")
        return 2
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

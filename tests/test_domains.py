"""One ROS domain per course process, machine-wide: also across Unix users (a classroom server)."""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import tempfile

import pytest

from course_helpers.core import domains

KERNELS_PER_USER = 25
USERS = ("course_domain_a", "course_domain_b")


def _ensure_user(name: str) -> pwd.struct_passwd:
    try:
        return pwd.getpwnam(name)
    except KeyError:
        subprocess.run(["useradd", "--no-create-home", "--shell", "/usr/sbin/nologin", name], check=True)
        return pwd.getpwnam(name)


def _hold_domain_as(user: pwd.struct_passwd, lock_dir: str):
    """Fork a process that becomes ``user``, reserves a domain and holds it until told to exit.

    Forking (not exec) keeps the already imported code: other users may not read this venv.
    Returns (pid, read end for the domain, write end to release it).
    """
    domain_r, domain_w = os.pipe()
    release_r, release_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        code = 1
        try:
            os.close(domain_r)
            os.close(release_w)
            os.setgroups([])
            os.setgid(user.pw_gid)
            os.setuid(user.pw_uid)
            os.environ[domains.LOCK_DIR_ENV] = lock_dir
            domains._held.clear()
            os.write(domain_w, str(domains.reserve_domain()).encode())
            os.close(domain_w)
            os.read(release_r, 1)  # hold the lock until the parent says so
            code = 0
        except BaseException as exc:
            os.write(domain_w, f"error {type(exc).__name__}: {exc}".encode())
        finally:
            os._exit(code)
    os.close(domain_w)
    os.close(release_r)
    return pid, domain_r, release_w


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to create two Unix users and act as them")
def test_two_users_kernels_never_share_a_domain():
    users = [_ensure_user(name) for name in USERS]
    base = tempfile.mkdtemp(prefix="course-domains-test-")
    os.chmod(base, 0o1777)  # like /tmp: every user may create the lock directory in it
    lock_dir = os.path.join(base, "ros2-course-domains")  # created by the first kernel, as its user
    holders = []
    try:
        for _ in range(KERNELS_PER_USER):
            for user in users:  # interleaved, as two classes of students starting kernels
                holders.append((user.pw_name, *_hold_domain_as(user, lock_dir)))
        chosen = []
        for name, _pid, domain_r, _release in holders:
            text = os.read(domain_r, 200).decode()
            os.close(domain_r)
            assert text.isdigit(), f"{name}: {text}"
            chosen.append((int(text), name))
        numbers = [domain for domain, _ in chosen]
        assert len(set(numbers)) == len(numbers), f"shared domains: {sorted(chosen)}"
        assert {name for _, name in chosen} == set(USERS)
        mode = os.stat(lock_dir).st_mode
        assert mode & 0o1777 == 0o1777, oct(mode)  # sticky and writable by every user
    finally:
        for _name, pid, _domain_r, release in holders:
            try:
                os.write(release, b"x")
            except BrokenPipeError:  # that holder has already exited (its error is reported above)
                pass
            os.close(release)
            os.waitpid(pid, 0)
        shutil.rmtree(base, ignore_errors=True)


def test_a_released_domain_can_be_taken_again_and_a_held_one_is_skipped(tmp_path, monkeypatch):
    monkeypatch.setenv(domains.LOCK_DIR_ENV, str(tmp_path / "locks"))
    first = domains.reserve_domain()
    second = domains.reserve_domain()
    assert first != second
    assert oct(os.stat(tmp_path / "locks").st_mode & 0o7777) == oct(0o1777)


def test_a_bad_domain_id_is_named():
    with pytest.raises(domains.CourseError, match="ROS_DOMAIN_ID must be a whole number from 0 to 232"):
        domains.parse_domain_id("300")

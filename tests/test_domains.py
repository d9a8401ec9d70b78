"""One ROS domain per course process, machine-wide: also across Unix users, and against a hostile one.

A reservation is an abstract Unix socket (``core/domains.py``). The tests that act as other Unix
users need root (to create the users and become them); the others run as anyone.
"""

from __future__ import annotations

import os
import pwd
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from course_helpers.core import domains

from .shared_install import ensure_user

KERNELS_PER_USER = 25
HOSTILE_KERNELS = 12
USERS = ("course_domain_a", "course_domain_b")
HOSTILE = "course_domain_x"
needs_root = pytest.mark.skipif(os.geteuid() != 0, reason="needs root to create Unix users and act as them")


class Holder:
    """A forked process that becomes a Unix user, runs ``job`` and holds what it took until released.

    Forking (not exec) keeps the already imported code: other users may not read this venv.
    ``result`` is what ``job`` returned (an int), or the error it raised, as text.
    """

    def __init__(self, user: pwd.struct_passwd | None, job, env: dict[str, str] | None = None):
        result_r, result_w = os.pipe()
        release_r, self._release = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:  # the child: never returns into pytest
            code = 1
            try:
                os.close(result_r)
                os.close(self._release)
                if user is not None:
                    os.setgroups([])
                    os.setgid(user.pw_gid)
                    os.setuid(user.pw_uid)
                os.environ.update(env or {})
                domains._held.clear()  # the fork copied the parent's reservations: not this process's
                os.write(result_w, str(job()).encode())
                os.close(result_w)
                os.read(release_r, 1)  # hold until the parent says so
                code = 0
            except BaseException as exc:
                os.write(result_w, f"error {type(exc).__name__}: {exc}".encode())
            finally:
                os._exit(code)
        os.close(result_w)
        os.close(release_r)
        self.result = os.read(result_r, 500).decode()
        os.close(result_r)

    @property
    def domain(self) -> int:
        assert self.result.isdigit(), self.result
        return int(self.result)

    def release(self) -> None:
        """Let it exit (a normal exit, which frees its reservations) and reap it."""
        try:
            os.write(self._release, b"x")
        except BrokenPipeError:  # it has exited already (its error is in ``result``)
            pass
        os.close(self._release)
        os.waitpid(self.pid, 0)

    def kill(self) -> None:
        """SIGKILL it, as a crash would, and reap it."""
        os.kill(self.pid, signal.SIGKILL)
        os.close(self._release)
        os.waitpid(self.pid, 0)


def _release_all(holders: list[Holder]) -> None:
    for holder in holders:
        holder.release()


def _contested(held: list[int]):
    """A reservation job that is offered every domain in ``held`` and one free domain, nothing else,
    and that free domain.

    Every domain outside those is excluded, so a kernel whose reservation failed to see a held
    domain would take it: only the operating system's view of ``held`` sends it to the free one.
    """
    free = next(d for d in range(domains.FIRST_DOMAIN, domains.LAST_DOMAIN + 1)
                if d not in held and domains.domain_free(d))
    offered = {*held, free}
    excluded = tuple(d for d in range(domains.FIRST_DOMAIN, domains.LAST_DOMAIN + 1) if d not in offered)
    return (lambda: domains.reserve_domain(exclude=excluded)), free


def _contested_holder(user, held: list[int], env: dict[str, str] | None = None) -> Holder:
    """A :class:`Holder` of a :func:`_contested` job. Other tests' kernels start meanwhile on this
    machine: when one of them took the offered free domain first (the job found every domain it was
    offered held, and that one is no longer free), the job is offered another free domain."""
    for _ in range(5):
        job, free = _contested(held)
        holder = Holder(user, job, env=env)
        failed = holder.result.startswith("error CourseError: all ROS domains")
        taken_meanwhile = failed and not domains.domain_free(free)
        if not taken_meanwhile:
            return holder
        holder.release()
    return holder


def _assert_released(domain: int, pid: int) -> None:
    """``pid`` (exited and reaped) left ``domain`` free. Other tests' kernels start meanwhile on this
    machine and may take the freed name at once: then a live process that is not ``pid`` holds it,
    which also proves the name was freed (a name has one socket at a time)."""
    if domains.domain_free(domain):
        return
    holders = domains.domain_holders(domain)
    assert holders and pid not in holders, f"domain {domain} still held after {pid} exited: {holders}"


@pytest.fixture
def shared_tmp():
    """A folder every user may write to, like /tmp (pytest's own tmp_path is private to root)."""
    path = Path(tempfile.mkdtemp(prefix="course-domains-test-"))
    os.chmod(path, 0o1777)
    yield path
    shutil.rmtree(path, ignore_errors=True)


@needs_root
def test_two_users_kernels_never_share_a_domain():
    users = [ensure_user(name) for name in USERS]
    holders = []
    try:
        for _ in range(KERNELS_PER_USER):
            for user in users:  # interleaved, as two classes of students starting kernels
                holders.append(_contested_holder(user, [h.domain for h in holders]))
        chosen = sorted(holder.domain for holder in holders)
        assert len(set(chosen)) == len(chosen), f"shared domains: {chosen}"
    finally:
        _release_all(holders)


@needs_root
def test_a_hostile_user_can_neither_take_nor_block_another_users_domain(shared_tmp):
    victim_user, hostile_user = ensure_user(USERS[0]), ensure_user(HOSTILE)
    victim = Holder(victim_user, domains.reserve_domain)
    hostile: list[Holder] = []
    try:
        name = domains.socket_name(victim.domain)

        def attack() -> int:
            """Everything an ordinary user can do to the reservation without keeping a process alive:
            bind the victim's name, connect to it, and leave a directory and files where the old
            scheme kept its lock files. Returns how many binds succeeded."""
            import socket

            taken = 0
            for domain in range(domains.FIRST_DOMAIN, domains.LAST_DOMAIN + 1):
                sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                try:
                    sock.bind(b"\0" + domains.socket_name(domain).encode())
                    taken += domain == victim.domain
                except OSError:
                    pass
                sock.close()  # a squat that ends with the process
            probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                probe.connect(b"\0" + name.encode())
                probe.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            probe.close()
            blockade = shared_tmp / "ros2-course-domains"
            blockade.mkdir(mode=0o700, exist_ok=True)
            for domain in range(domains.FIRST_DOMAIN, domains.LAST_DOMAIN + 1):
                (blockade / f"domain-{domain}.lock").touch(mode=0o600)
            return taken

        squatter = Holder(hostile_user, attack, env={"TMPDIR": str(shared_tmp)})
        assert squatter.result == "0", f"the hostile user bound the victim's name: {squatter.result}"
        squatter.release()
        # The hostile user now starts kernels, each offered the victim's domain: none lands on it.
        for _ in range(HOSTILE_KERNELS):
            hostile.append(_contested_holder(hostile_user, [victim.domain, *(h.domain for h in hostile)],
                                             env={"TMPDIR": str(shared_tmp)}))
        taken = [holder.domain for holder in hostile]
        assert victim.domain not in taken, f"a hostile kernel got the victim's domain {victim.domain}"
        assert len(set(taken)) == HOSTILE_KERNELS, taken
        # ... and after the squat attempt and with the hostile kernels alive, a third user gets a domain.
        other = Holder(ensure_user(USERS[1]), domains.reserve_domain)
        try:
            assert other.domain not in {victim.domain, *taken}
        finally:
            other.release()
    finally:
        _release_all([victim, *hostile])


@needs_root
def test_a_per_user_tmpdir_changes_nothing(shared_tmp):
    """pam_tmpdir or systemd give each user a TMPDIR of their own: reservations do not follow it."""
    holders = []
    try:
        for index, name in enumerate(USERS):
            own_tmp = shared_tmp / name
            own_tmp.mkdir()
            user = ensure_user(name)
            os.chown(own_tmp, user.pw_uid, user.pw_gid)
            for _ in range(5):
                held = [h.domain for h in holders]
                holders.append(_contested_holder(user, held, env={"TMPDIR": str(own_tmp)}))
            assert len(holders) == 5 * (index + 1)
        chosen = [holder.domain for holder in holders]
        assert len(set(chosen)) == len(chosen), f"per-user TMPDIRs let kernels share domains: {chosen}"
    finally:
        _release_all(holders)


def test_a_domain_held_by_another_process_is_skipped_and_taken_again_once_it_exits():
    holder = Holder(None, domains.reserve_domain)
    try:
        held = holder.domain
        assert not domains.domain_free(held)
        assert os.getpid() not in domains.domain_holders(held)
        assert holder.pid in domains.domain_holders(held)
        # Offer this process only the held domain and one free neighbour: the operating system's
        # reservation (not this process's own records) makes it skip the held one.
        others = [d for d in range(domains.FIRST_DOMAIN, domains.LAST_DOMAIN + 1) if d != held]
        for _ in range(5):  # another test's kernel may take the spare first: offer another
            spare = next(d for d in others if domains.domain_free(d))
            try:
                mine = domains.reserve_domain(exclude=tuple(d for d in others if d != spare))
                break
            except domains.CourseError:
                assert not domains.domain_free(spare)
        assert mine == spare
    finally:
        holder.kill()  # a crash: nothing is left to clean, the name is free at once
    _assert_released(held, holder.pid)
    try:
        again = domains.reserve_domain(exclude=tuple(d for d in others))
    except domains.CourseError:  # another test's kernel took it between the two lines
        _assert_released(held, holder.pid)
    else:
        assert again == held and domains.held_here(held)


def test_a_reservation_leaves_nothing_on_disk_and_ignores_tmpdir(tmp_path):
    env = dict(os.environ, TMPDIR=str(tmp_path))
    code = ("import os; from course_helpers.core import domains; d = domains.reserve_domain(); "
            "print(d, domains.held_here(d), os.getpid())")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    domain, held, pid = out.stdout.split()
    assert held == "True"
    assert list(tmp_path.iterdir()) == []
    _assert_released(int(domain), int(pid))  # released with its process


def test_a_domain_set_by_the_user_is_not_a_reservation():
    code = ("import os; from course_helpers.core import domains; os.environ['ROS_DOMAIN_ID'] = '0'; "
            "choice = domains.choose_domain(); print(choice.source, domains.held_here(choice.domain_id))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["user", "False"]


def test_a_bad_domain_id_is_named():
    with pytest.raises(domains.CourseError, match="ROS_DOMAIN_ID must be a whole number from 0 to 232"):
        domains.parse_domain_id("300")


def test_the_holders_of_domains_are_listed_with_user_pid_and_command():
    """``python -m course_helpers.core.domains``: what an instructor runs to see who holds what."""
    holder = Holder(None, domains.reserve_domain)
    try:
        out = subprocess.run([sys.executable, "-m", "course_helpers.core.domains"], capture_output=True,
                             text=True, check=True, timeout=60).stdout
        user = pwd.getpwuid(os.getuid()).pw_name
        assert f"domain {holder.domain:>3}  {user} {holder.pid} " in out, out
    finally:
        holder.kill()
    out = subprocess.run([sys.executable, "-m", "course_helpers.core.domains"], capture_output=True,
                         text=True, check=True, timeout=60).stdout
    # Gone from the list. Another test's kernel may hold the freed domain by now: a different line.
    assert f"domain {holder.domain:>3}  {user} {holder.pid} " not in out, out

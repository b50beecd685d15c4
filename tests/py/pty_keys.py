"""Runs a command on a pseudo-terminal and types keys into it, as an operator at a keyboard.

    pty_keys.py TIMEOUT_S -- CMD [ARGS...]

Each line read on stdin is one key: `space`, `enter`, `esc`, `ctrl-c` or a single character.
At the end of stdin no more keys are typed; the command then has TIMEOUT_S seconds to exit
(else it is killed); after 120 s more it is killed anyway. Prints JSON {"returncode": N or null, "output": "..."} with everything the
command wrote to the terminal.
"""
import json
import os
import pty
import select
import signal
import sys
import time

KEYS = {"space": b" ", "enter": b"\r", "esc": b"\x1b", "ctrl-c": b"\x03"}


def main():
    timeout_s = float(sys.argv[1])
    assert sys.argv[2] == "--", "usage: pty_keys.py TIMEOUT_S -- CMD [ARGS...]"
    cmd = sys.argv[3:]
    pid, fd = pty.fork()
    if pid == 0:
        os.execvp(cmd[0], cmd)
    out = bytearray()
    stdin_open, deadline, status = True, None, None
    give_up = time.monotonic() + 120 + timeout_s  # however the caller behaves
    while status is None:
        now = time.monotonic()
        if (deadline is not None and now > deadline) or now > give_up:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            break
        watch = [fd] + ([sys.stdin] if stdin_open else [])
        ready, _, _ = select.select(watch, [], [], 0.05)
        if fd in ready:
            try:
                out += os.read(fd, 65536)
            except OSError:  # the child closed the terminal
                pass
        if sys.stdin in ready:
            line = sys.stdin.readline()
            if not line:
                stdin_open, deadline = False, time.monotonic() + timeout_s
            else:
                key = line.strip()
                os.write(fd, KEYS.get(key, key.encode()))
        done, code = os.waitpid(pid, os.WNOHANG)
        if done:
            status = os.waitstatus_to_exitcode(code)
    # Whatever is left in the terminal's buffer.
    while True:
        try:
            ready, _, _ = select.select([fd], [], [], 0.05)
            if not ready:
                break
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            out += chunk
        except OSError:
            break
    print(json.dumps({"returncode": status, "output": out.decode("utf-8", "replace")}))


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Starts a Type=notify daemon as systemd would and waits for its READY=1.

    notify_start.py DIR TIMEOUT_S LOG -- COMMAND [ARG]...

Binds a notification socket in DIR (which the daemon's user can reach), starts COMMAND with
NOTIFY_SOCKET pointing there and its output in LOG, and prints the daemon's PID once READY=1
arrives (exit 0). If the daemon exits first or TIMEOUT_S passes, prints LOG and exits 1 (the
daemon is killed on timeout). The daemon keeps running after this returns. With
NOTIFY_START_ROOT=R in the environment the daemon runs in a chroot R (DIR is under R): its
NOTIFY_SOCKET is the path as seen inside.
"""
import os
import socket
import subprocess
import sys


def main() -> int:
    directory, timeout, log = sys.argv[1], float(sys.argv[2]), sys.argv[3]
    command = sys.argv[sys.argv.index("--") + 1:]
    path = os.path.join(directory, "notify-%d.sock" % os.getpid())
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(path)
    os.chmod(path, 0o777)  # the daemon runs as another user; the directory limits who reaches it
    root = os.environ.pop("NOTIFY_START_ROOT", "").rstrip("/")
    seen = path[len(root):] if root and path.startswith(root + "/") else path
    env = dict(os.environ, NOTIFY_SOCKET=seen)
    with open(log, "wb") as out:
        proc = subprocess.Popen(command, env=env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
    sock.settimeout(0.2)
    waited = 0.0
    try:
        while waited < timeout:
            try:
                message = sock.recv(4096).decode(errors="replace")
            except socket.timeout:
                waited += 0.2
                if proc.poll() is not None:
                    break
                continue
            if "READY=1" in message.split("\n"):
                print(proc.pid)
                return 0
        if proc.poll() is None:
            proc.kill()
            proc.wait()
            print("daemon sent no READY=1 within %.0f s" % timeout, file=sys.stderr)
        else:
            print("daemon exited with %d before READY=1" % proc.returncode, file=sys.stderr)
        sys.stderr.write(open(log, errors="replace").read())
        return 1
    finally:
        sock.close()
        os.unlink(path)


if __name__ == "__main__":
    sys.exit(main())

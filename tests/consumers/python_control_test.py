#!/usr/bin/env python3
"""ds1928.Control finds its socket like ds1928ctl: the path given, else $DS1928_SOCKET, else the
default, each followed by the per-user fallback; none answering raises DaemonUnreachable naming
every path tried. A stand-in daemon (a Unix socket answering one status line) in this process.

Usage: python_control_test.py BUILD_DIR SOURCE_DIR
"""
import json
import os
import socket
import sys
import tempfile
import threading

sys.path.insert(0, os.path.join(sys.argv[2], "python"))
import ds1928  # noqa: E402

failures = 0


def check(what, ok, detail=""):
    global failures
    print(("ok:   " if ok else "FAIL: ") + what + (f" ({detail})" if detail and not ok else ""))
    failures += 0 if ok else 1


def serve(path):
    """Answers every request line on `path` with {"ok":true,"id":...,"served_by":path}."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path)
    listener.listen(8)

    def run():
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            with conn:
                buffer = b""
                while b"\n" not in buffer:
                    chunk = conn.recv(4096)
                    if not chunk:
                        break
                    buffer += chunk
                if b"\n" in buffer:
                    request = json.loads(buffer.split(b"\n", 1)[0])
                    conn.sendall((json.dumps({"ok": True, "id": request.get("id"),
                                              "served_by": path}) + "\n").encode())

    threading.Thread(target=run, daemon=True).start()
    return listener


def main():
    with tempfile.TemporaryDirectory(prefix="ds1928-pyctl-") as tmp:
        os.environ.pop("DS1928_SOCKET", None)
        os.environ["XDG_RUNTIME_DIR"] = tmp
        fallen = os.path.join(tmp, "ds1928d", "fallen.sock")
        listener = serve(fallen)
        missing = "/nonexistent-ds1928/fallen.sock"

        check("fallback path as the daemon computes it",
              ds1928.control.fallback_socket_path(missing) == fallen,
              ds1928.control.fallback_socket_path(missing))
        with ds1928.Control(missing, timeout=5) as c:
            check("a daemon that fell back is found", c.path == fallen, c.path)
            check("and answers", c.status().get("served_by") == fallen)

        os.environ["DS1928_SOCKET"] = missing
        with ds1928.Control(timeout=5) as c:
            check("$DS1928_SOCKET, then its fallback", c.path == fallen, c.path)
        other = "/nonexistent-ds1928/other.sock"
        try:
            ds1928.Control(other, timeout=5)
            check("the path given wins over $DS1928_SOCKET", False, "connected")
        except ds1928.DaemonUnreachable as e:
            check("the path given wins over $DS1928_SOCKET",
                  e.paths == [other, os.path.join(tmp, "ds1928d", "other.sock")], str(e.paths))
            text = str(e)
            check("the error names every path tried",
                  other in text and os.path.join(tmp, "ds1928d", "other.sock") in text and
                  "No such file" in text and "is ds1928d running?" in text, text)
            check("DaemonUnreachable is a ConnectionError", isinstance(e, ConnectionError))

        del os.environ["XDG_RUNTIME_DIR"]
        try:
            ds1928.Control(other, timeout=5)
        except ds1928.DaemonUnreachable as e:
            check("without XDG_RUNTIME_DIR: /tmp/ds1928d-<uid>/",
                  e.paths[1] == f"/tmp/ds1928d-{os.getuid()}/other.sock", str(e.paths))
        listener.close()
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())

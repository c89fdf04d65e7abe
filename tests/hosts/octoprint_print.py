#!/usr/bin/env python3
"""A real OctoPrint server prints a file to a serial port, through its REST
API only, as a user would through its web page.

    octoprint_print.py BASEDIR SERIAL_PORT GCODE HTTP_PORT JOBS TIMEOUT_S

BASEDIR: a fresh, empty directory for OctoPrint's configuration. The only
settings written are the ones a headless first start needs: the first-run
wizard marked done, an admin user (access control cannot be turned off), and
SERIAL_PORT as an additional serial port (OctoPrint lists only usual serial
device names). Everything else, the serial communication above all, keeps
OctoPrint's defaults.

The script connects at 115200, uploads GCODE, then prints it JOBS times.
After each job it sends `M400` and `M114` through the API and prints
`PRINTED <k>` on stdout, then waits for a line on stdin (`next` or `quit`):
the caller checks the final position in the serial transcript it records,
and may change the line (noise) before the next job. Other stdout lines:
`EVENT <text>` for progress, `TEMPS <json>` with the temperatures OctoPrint
showed during each job, `STATE <json>` when a job ended. Exit code 0 when
every job reached the end; otherwise a message and OctoPrint's log tail.
"""

import json
import os
import subprocess
import sys
import time

import requests

BASEDIR, SERIAL_PORT, GCODE, HTTP_PORT, JOBS, TIMEOUT_S = sys.argv[1:7]
HTTP_PORT, JOBS, TIMEOUT_S = int(HTTP_PORT), int(JOBS), float(TIMEOUT_S)
URL = f"http://127.0.0.1:{HTTP_PORT}"
VENV_BIN = os.path.dirname(sys.executable)
OCTOPRINT = os.path.join(VENV_BIN, "octoprint")
PASSWORD = "ferrostep-test"


def say(*words):
    print(*words, flush=True)


def log_tail(lines=80):
    path = os.path.join(BASEDIR, "logs", "octoprint.log")
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return "".join(f.readlines()[-lines:])
    except OSError as e:
        return f"(no octoprint.log: {e})"


def fail(message):
    say(f"FAILED {message}")
    try:
        with open(os.path.join(BASEDIR, "serve-output.txt"), encoding="utf-8", errors="replace") as f:
            output = f.read()[-2000:]
    except OSError:
        output = ""
    sys.stderr.write(f"{message}\n--- octoprint serve's output ---\n{output}\n--- octoprint.log (tail) ---\n{log_tail()}\n")
    sys.exit(1)


def die_with_parent():
    """In the server's process: SIGTERM when this script dies (a test that
    panics kills the script; the server must not outlive it)."""
    import ctypes
    import signal

    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def configure():
    os.makedirs(BASEDIR, exist_ok=True)
    with open(os.path.join(BASEDIR, "config.yaml"), "w", encoding="utf-8") as f:
        f.write("server:\n  firstRun: false\n")
        f.write(f"serial:\n  additionalPorts:\n  - {SERIAL_PORT}\n")
    subprocess.run(
        [OCTOPRINT, "--basedir", BASEDIR, "user", "add", "--password", PASSWORD, "--admin", "admin"],
        check=True,
        stdout=subprocess.DEVNULL,
    )


class Api:
    def __init__(self):
        self.session = requests.Session()

    def _csrf(self):
        for cookie in self.session.cookies:
            if cookie.name.startswith("csrf_token"):
                return {"X-CSRF-Token": cookie.value}
        return {}

    def get(self, path):
        response = self.session.get(URL + path, timeout=30)
        response.raise_for_status()
        return response.json()

    def post(self, path, **kwargs):
        response = self.session.post(URL + path, headers=self._csrf(), timeout=60, **kwargs)
        if response.status_code >= 400:
            fail(f"POST {path}: {response.status_code} {response.text}")
        return response

    def login(self):
        # The page sets the CSRF cookie that every POST must echo.
        self.session.get(URL + "/", timeout=60)
        self.post("/api/login", json={"user": "admin", "pass": PASSWORD, "remember": False})


def wait_for_server(server):
    end = time.time() + 180
    while time.time() < end:
        if server.poll() is not None:
            fail(f"octoprint serve exited with {server.returncode}")
        try:
            requests.get(URL + "/api/currentuser", timeout=5)
            return
        except requests.RequestException:
            time.sleep(0.5)
    fail("the OctoPrint server did not answer within 180 s")


def connect(api):
    options = api.get("/api/connection")["options"]
    if SERIAL_PORT not in options["ports"]:
        fail(f"OctoPrint does not list {SERIAL_PORT}: {options['ports']}")
    api.post("/api/connection", json={"command": "connect", "port": SERIAL_PORT, "baudrate": 115200})
    end = time.time() + 120
    while time.time() < end:
        state = api.get("/api/connection")["current"]["state"]
        if state == "Operational":
            say(f"EVENT connected: {state}")
            return
        if state.startswith("Error") or state.startswith("Offline"):
            fail(f"connection failed: {state}")
        time.sleep(0.5)
    fail(f"not operational within 120 s: {state}")


def print_job(api, k, filename):
    # Select and start (the first time the upload does both).
    if k == 1:
        with open(GCODE, "rb") as f:
            api.post("/api/files/local", files={"file": (filename, f)}, data={"select": "true", "print": "true"})
    else:
        api.post(f"/api/files/local/{filename}", json={"command": "select", "print": True})
    say(f"EVENT job {k} started")
    temps = {"tool0": [], "bed": []}
    seen_printing = False
    end = time.time() + TIMEOUT_S
    last = None
    while time.time() < end:
        job = api.get("/api/job")
        state = job["state"]
        try:
            printer = api.get("/api/printer?exclude=sd")
            for name in temps:
                reading = printer["temperature"].get(name)
                if reading and reading.get("actual") is not None:
                    temps[name].append((round(reading["actual"], 2), reading.get("target")))
        except requests.HTTPError:
            pass  # 409 while the printer is not operational
        if state != last:
            say(f"EVENT job {k}: {state} {job['progress']}")
            last = state
        if state in ("Printing", "Starting", "Starting to print"):
            seen_printing = True
        elif seen_printing and state == "Operational":
            say("STATE " + json.dumps({"job": k, "state": state, "progress": job["progress"]}))
            say("TEMPS " + json.dumps({"job": k, **temps}))
            return
        elif state.startswith("Error") or state.startswith("Offline") or state == "Cancelling":
            fail(f"job {k} ended in state {state!r}: {job}")
        time.sleep(1.0)
    fail(f"job {k} not done within {TIMEOUT_S} s (state {last})")


def main():
    configure()
    command = [OCTOPRINT, "--basedir", BASEDIR, "serve", "--host", "127.0.0.1", "--port", str(HTTP_PORT)]
    if os.geteuid() == 0:
        # OctoPrint refuses root unless told (CI containers run as root).
        command.append("--iknowwhatimdoing")
    server_output = open(os.path.join(BASEDIR, "serve-output.txt"), "w", encoding="utf-8")
    server = subprocess.Popen(command, stdout=server_output, stderr=subprocess.STDOUT, preexec_fn=die_with_parent)
    try:
        wait_for_server(server)
        api = Api()
        api.login()
        say("EVENT logged in")
        connect(api)
        filename = os.path.basename(GCODE)
        for k in range(1, JOBS + 1):
            print_job(api, k, filename)
            api.post("/api/printer/command", json={"commands": ["M400", "M114"]})
            say(f"PRINTED {k}")
            answer = sys.stdin.readline().strip()
            if answer != "next":
                break
        api.post("/api/connection", json={"command": "disconnect"})
        with open(os.path.join(BASEDIR, "logs", "octoprint.log"), encoding="utf-8", errors="replace") as f:
            for line in f:
                if "Printer reports firmware name" in line or "Firmware states that it supports" in line:
                    say("LOG " + line.strip())
    finally:
        server.terminate()
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()


if __name__ == "__main__":
    main()

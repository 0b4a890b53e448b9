"""External test program with misbehaviours, used by tests/simulators/test_command.py.

Usage: tool.py MODE [ARGS...], run in a run folder that holds forcing.csv.

record FILE ARGS...   write {"argv", "files", "env"} as JSON to FILE and a valid out.csv
fail                  print a message to stderr and exit with code 3
sleep SECONDS PIDFILE start a child that sleeps, write both pids to PIDFILE, sleep
nooutput              exit 0 without writing out.csv
garbage               write an out.csv that is not CSV
nan                   write an out.csv with a NaN value
short                 write an out.csv with one row too few
offclock              write an out.csv whose time column is off the forcing clock
"""

import json
import os
import subprocess
import sys
import time


def n_samples() -> int:
    with open("forcing.csv", encoding="utf-8") as f:
        return sum(1 for line in f if line.strip()) - 1


def write_out(values, times=None) -> None:
    times = times if times is not None else [600.0 * i for i in range(len(values))]
    with open("out.csv", "w", encoding="utf-8") as f:
        f.write("time,y\n")
        for t, v in zip(times, values, strict=True):
            f.write(f"{t!r},{v!r}\n")


def main() -> int:
    mode, args = sys.argv[1], sys.argv[2:]
    n = n_samples()
    if mode == "record":
        record = {
            "argv": args[1:],
            "files": sorted(os.listdir(".")),
            "env": os.environ.get("BAYESCAL_TEST_VAR"),
        }
        with open(args[0], "w", encoding="utf-8") as f:
            json.dump(record, f)
        write_out([float(i) for i in range(n)])
    elif mode == "fail":
        print("rc_wall: parameter R is negative, cannot continue", file=sys.stderr)
        return 3
    elif mode == "sleep":
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        with open(args[1], "w", encoding="utf-8") as f:
            f.write(f"{os.getpid()} {child.pid}\n")
        time.sleep(float(args[0]))
    elif mode == "garbage":
        with open("out.csv", "wb") as f:
            f.write(b'time,y\n"unterminated,1\n\x00\xff\xfe\n')
    elif mode == "nan":
        write_out([0.0] * (n - 1) + [float("nan")])
    elif mode == "short":
        write_out([0.0] * (n - 1))
    elif mode == "offclock":
        write_out([0.0] * n, [601.0 * i for i in range(n)])
    elif mode != "nooutput":
        print(f"unknown mode {mode}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())

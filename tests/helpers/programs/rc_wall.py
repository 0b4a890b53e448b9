"""External test program: a one-node RC wall (used by tests/simulators/test_command.py).

Reads ``params.txt`` (lines ``name = value`` with R [m²K/W], C [J/(m²K)] and
T0 [°C]) and ``forcing.csv`` (columns ``time`` [s] and ``temp_air_out`` [°C]),
solves ``C dT/dt = (T_out - T)/R`` exactly for an input that is linear between
samples and writes ``out.csv`` with columns ``time``, ``T`` [°C] and
``q`` = (T_out - T)/R [W/m²], all with 17 significant digits.
Usage: rc_wall.py [OUTPUT_CSV]
"""

import csv
import math
import sys


def main() -> int:
    params = {}
    with open("params.txt", encoding="utf-8") as f:
        for line in f:
            if "=" in line:
                key, value = line.split("=", 1)
                params[key.strip()] = float(value)
    r, c, temp = params["R"], params["C"], params["T0"]
    with open("forcing.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    times = [float(row["time"]) for row in rows]
    u = [float(row["temp_air_out"]) for row in rows]
    tau = r * c
    out = [(times[0], temp, (u[0] - temp) / r)]
    for i in range(len(u) - 1):
        h = times[i + 1] - times[i]
        slope = (u[i + 1] - u[i]) / h
        # particular solution u(t) - slope*tau plus the decaying homogeneous part
        temp = u[i + 1] - slope * tau + (temp - u[i] + slope * tau) * math.exp(-h / tau)
        out.append((times[i + 1], temp, (u[i + 1] - temp) / r))
    target = sys.argv[1] if len(sys.argv) > 1 else "out.csv"
    with open(target, "w", encoding="utf-8") as f:
        f.write("time,T,q\n")
        for row in out:
            f.write(",".join(repr(x) for x in row) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

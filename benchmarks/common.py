"""Helpers shared by the benchmark scripts."""
import csv
import os


def write_csv(rows, path):
    """Write a list of dicts as CSV atomically: never a half-written file."""
    with open(path + ".tmp", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(path + ".tmp", path)

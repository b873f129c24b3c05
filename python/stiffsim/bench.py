"""The reports of `stiffsim bench`, with their tables as lists of dicts.

Each function runs the report in the library (as the CLI does), which writes
<name>.csv and <name>.md into `out` (a temporary directory when None), and
returns the CSV's rows, numbers converted to int or float.
"""

import csv
import os
import tempfile

from . import _stiffsim


def _value(text):
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def _report(name, out, quick, models, verbose):
    def run_in(directory):
        _stiffsim._run_report(name, str(directory), bool(quick),
                              str(models) if models else _stiffsim.models_dir, bool(verbose))
        with open(os.path.join(str(directory), name + ".csv"), newline="") as f:
            return [{k: _value(v) for k, v in row.items()} for row in csv.DictReader(f)]

    if out is not None:
        return run_in(out)
    with tempfile.TemporaryDirectory(prefix="stiffsim-" + name + "-") as directory:
        return run_in(directory)


def precision(out=None, quick=False, models=None, verbose=False):
    """Work-precision: error against wall time of every method (precision.csv rows)."""
    return _report("precision", out, quick, models, verbose)


def scaling(out=None, quick=False, models=None, verbose=False):
    """Time per step against size (scaling.csv rows)."""
    return _report("scaling", out, quick, models, verbose)


def stability(out=None, quick=False, models=None, verbose=False):
    """Stiff and extreme cases (stability.csv rows)."""
    return _report("stability", out, quick, models, verbose)

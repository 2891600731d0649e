#!/usr/bin/python3
"""Keep a main job's validation report beside the earlier ones, and set the model's targets
against the mean over every kept job (scripts/model-bias.py): one job cannot tell the model's
error from the host's noise, several can.

    /usr/bin/python3 scripts/keep-job.py DIR

DIR is a main job's results folder (results/<host>/). Its validation.json is copied to
DIR/jobs/<commit>_<timestamp>/validation.json (the same job kept twice is one folder); with two
or more kept, DIR/bias.json (as measured), DIR/bias_own_speed.json (at each run's own host
speed) and DIR/bias.md (both tables and their targets against the expected error) are written
from all of them, and validation.md's summary quotes them (scripts/plot-model.py). With fewer,
those three are removed. The main job calls it after every full job (not --quick: its figures
mean nothing). Keep in jobs/ only jobs of the model you are judging: delete the folders of
jobs run on other code or another machine. Bad input exits 2 with one line and writes nothing.
"""
import contextlib
import glob
import importlib.util
import io
import os
import re
import shutil
import sys

from script_common import InputError, load_report

HERE = os.path.dirname(os.path.abspath(__file__))
MIN_JOBS = 2  # model-bias.py needs two reports to tell bias from noise


def model_bias():
    """scripts/model-bias.py as a module (its file name is not an identifier)."""
    spec = importlib.util.spec_from_file_location("model_bias", os.path.join(HERE, "model-bias.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def job_name(doc, path):
    commit, stamp = str(doc.get("git_commit") or ""), str(doc.get("timestamp") or "")
    if not commit or not stamp:
        raise InputError(f"{path} has no git_commit or timestamp to name the kept job by")
    return f"{commit[:8]}_{re.sub(r'[^0-9A-Za-z]', '', stamp)}"


def keep(directory):
    src = os.path.join(directory, "validation.json")
    doc = load_report(src, "sphmodel-validation", "a sphmodel validation report")
    dest = os.path.join(directory, "jobs", job_name(doc, src))
    os.makedirs(dest, exist_ok=True)
    shutil.copyfile(src, os.path.join(dest, "validation.json.tmp"))
    os.replace(os.path.join(dest, "validation.json.tmp"), os.path.join(dest, "validation.json"))
    print(f"keep-job.py: kept {dest}")
    return sorted(glob.glob(os.path.join(directory, "jobs", "*", "validation.json")))


def write_bias(directory, kept):
    outputs = [os.path.join(directory, f) for f in ("bias.json", "bias_own_speed.json", "bias.md")]
    if len(kept) < MIN_JOBS:
        for f in outputs:
            if os.path.exists(f):
                os.remove(f)
        print(f"keep-job.py: {len(kept)} job kept in {directory}/jobs; the bias over jobs needs "
              f"{MIN_JOBS}")
        return
    mb = model_bias()
    reports = [(p, mb.load_validation(p)) for p in kept]
    md = io.StringIO()
    md.write(f"# The model's bias over the {len(kept)} main jobs kept in jobs/\n\n"
             "`scripts/keep-job.py` after each full main job (`scripts/model-bias.py` over "
             "jobs/*/validation.json).\n")
    for own, name, title in ((False, "bias.json", "As measured"),
                             (True, "bias_own_speed.json", "At each run's own host speed (a "
                                                           "diagnostic)")):
        try:
            summary = mb.summarise(reports, own, mb.DEFAULT_MIN_JOBS)
        except InputError as e:  # e.g. the kept jobs share no configuration: no bias to give
            for f in outputs:
                if os.path.exists(f):
                    os.remove(f)
            print(f"keep-job.py: no bias over the kept jobs ({e})")
            return
        md.write(f"\n## {title}\n\n")
        with contextlib.redirect_stdout(md):
            mb.print_table(summary, reports, own, mb.DEFAULT_MIN_JOBS)
        with contextlib.redirect_stdout(io.StringIO()):  # write_json's "written" line
            mb.write_json(os.path.join(directory, name),
                          mb.report_json(summary, reports, own, "wall", mb.DEFAULT_MIN_JOBS))
    with open(outputs[2] + ".tmp", "w") as f:
        f.write(md.getvalue())
    os.replace(outputs[2] + ".tmp", outputs[2])
    print(f"keep-job.py: the bias over {len(kept)} kept jobs in {outputs[2]}")


def main():
    if len(sys.argv) == 2 and sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    if len(sys.argv) != 2:
        print(f"keep-job.py: {len(sys.argv) - 1} arguments given: expected one, a main job's "
              "results folder (see --help)", file=sys.stderr)
        sys.exit(2)
    directory = sys.argv[1]
    try:
        if not os.path.isdir(directory):
            raise InputError(f"{directory} is not a folder (expected a main job's results folder)")
        kept = keep(directory)
        write_bias(directory, kept)
    except InputError as e:
        print(f"keep-job.py: {e}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()

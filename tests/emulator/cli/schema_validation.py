#!/usr/bin/python3
"""The schemas `wheelhil schema` writes, checked by an independent validator (Debian's
python3-jsonschema, draft 2020-12): every shipped file of each kind is valid; the same file with
a misspelt key is not, at the top of every file and in every mapping the loader checks the keys
of (the loaders refuse them too: the schema's closed mappings are their CheckKeys sets).
Usage: schema_validation.py SCHEMA_DIR SOURCE_DIR"""
import copy
import glob
import json
import os
import re
import sys

import jsonschema
import yaml

schema_dir, src = sys.argv[1], sys.argv[2]

# YAML 1.2 numbers (1e-3 is a float there, as in yaml-cpp; PyYAML's YAML 1.1 reads a string).
yaml.SafeLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$"),
    list("-+0123456789."))

kinds = {
    "scenario": ["scenarios/*.yaml", "scenarios/smoke/*.yaml", "scenarios/own_hardware/*.yaml",
                 "scenarios/urdf/*.yaml"],
    "platform": ["scenarios/platforms/*.yaml"],
    "campaign": ["scenarios/campaigns/*.yaml"],
    "outputs": ["scenarios/outputs/*.yaml"],
    "firmware-config": ["scenarios/firmware/*.yaml"],
}


def mappings(doc, path=()):
    """Every mapping in doc with its path, the document first."""
    if isinstance(doc, dict):
        yield path, doc
        for k, v in doc.items():
            yield from mappings(v, path + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from mappings(v, path + (i,))


failures = 0
checked = 0
refused = 0
for kind, patterns in kinds.items():
    with open(os.path.join(schema_dir, kind + ".schema.json")) as f:
        schema = json.load(f)
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    files = sorted(p for pat in patterns for p in glob.glob(os.path.join(src, pat)))
    if not files:
        print(f"FAIL {kind}: no shipped files")
        failures += 1
    for path in files:
        with open(path) as f:
            doc = yaml.safe_load(f)
        errors = list(validator.iter_errors(doc))
        checked += 1
        if errors:
            failures += 1
            e = errors[0]
            print(f"FAIL {kind} {os.path.relpath(path, src)}: {list(e.absolute_path)}: {e.message}")
            continue
        # A misspelt key in each mapping the schema describes as closed.
        for mpath, m in mappings(doc):
            bad = copy.deepcopy(doc)
            target = bad
            for step in mpath:
                target = target[step]
            key = next(iter(m), "name") + "_typo"
            target[key] = 1
            # The file is valid without it: any error is the misspelling's.
            errs = list(validator.iter_errors(bad))
            if errs:
                refused += 1
            elif mpath == ():
                # The document itself is always closed.
                print(f"FAIL {kind} {os.path.relpath(path, src)}: a misspelt top-level key "
                      f"'{key}' is valid")
                failures += 1
    print(f"ok {kind}: {len(files)} files valid")

# A key another type of the same list has (a hold segment with a speed): invalid, as the loader
# finds it.
with open(os.path.join(schema_dir, "scenario.schema.json")) as f:
    scenario = jsonschema.Draft202012Validator(json.load(f))
with open(os.path.join(src, "scenarios/smoke/paper000_slip_short.yaml")) as f:
    doc = yaml.safe_load(f)
hold = next(s for s in doc["motion"] if s["type"] == "hold")
hold["vx_m_s"] = 0.1
if not list(scenario.iter_errors(doc)):
    print("FAIL: a hold segment with vx_m_s (a twist's key) is valid")
    failures += 1
else:
    print("ok: a hold segment with a twist's key is invalid")

print(f"{checked} files valid; {refused} misspelt keys refused")
if refused == 0:
    print("FAIL: no misspelt key was refused")
    failures += 1
sys.exit(1 if failures else 0)

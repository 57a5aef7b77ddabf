#!/usr/bin/env python3
"""Read GSD files with pyprofibus's GSD interpreter (an independent parser)
and print what it sees, one JSON object per file, for gsd_pyprofibus.rs.

Usage: pyprofibus_gsd.py [--fix-quirks] FILE...

--fix-quirks first rewrites the vendor quirks that our lenient parser
accepts and pyprofibus does not (a commented-out `;#Profibus_DP`,
`MaxTsd_` for `MaxTsdr_`, `Modules='name'` for `Module="name"`), so that
pyprofibus can be compared with our reading of such files.
"""

import json
import re
import sys

from pyprofibus.gsd.interp import GsdInterp

BAUDS = ["9.6", "19.2", "45.45", "93.75", "187.5", "500", "1.5M", "3M", "6M", "12M"]


def fix_quirks(text):
    text = re.sub(r"(?m)^;\s*(#Profibus_DP)\s*$", r"\1", text)
    text = re.sub(r"(?m)^MaxTsd_", "MaxTsdr_", text)
    text = re.sub(r"(?m)^(\s*)Modules\s*=\s*'([^']*)'", r'\1Module="\2"', text)
    return text


def main():
    args = sys.argv[1:]
    fix = False
    if args and args[0] == "--fix-quirks":
        fix = True
        args = args[1:]
    for path in args:
        with open(path, "rb") as f:
            data = f.read()
        if fix:
            data = fix_quirks(data.decode("latin_1")).encode("latin_1")
        try:
            gsd = GsdInterp.fromBytes(data, filename=path)
            modules = [
                {"name": m.name, "cfg": bytes(m.configBytes).hex()}
                for m in gsd.getField("Module", [])
            ]
            out = {
                "file": path,
                "ident": gsd.getField("Ident_Number"),
                "modular": bool(gsd.isModular()),
                "dpv1": bool(gsd.isDPV1()),
                "modules": modules,
                "supp": {b: bool(gsd.getField(b + "_supp", False)) for b in BAUDS},
                "max_tsdr": {b: gsd.getField("MaxTsdr_" + b) for b in BAUDS},
                "max_input_len": gsd.getField("Max_Input_Len"),
                "max_output_len": gsd.getField("Max_Output_Len"),
                "max_module": gsd.getField("Max_Module"),
                "user_prm_data": bytes(gsd.getUserPrmData()).hex(),
            }
        except Exception as e:  # report, the Rust side decides
            out = {"file": path, "error": "%s: %s" % (type(e).__name__, e)}
        print(json.dumps(out))


if __name__ == "__main__":
    main()

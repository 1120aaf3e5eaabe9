#!/usr/bin/env python3
"""Converts one JIGSAWS task to the layout of `cutlab import kinematics`.

JIGSAWS (the JHU-ISI Gesture and Skill Assessment Working Set) holds da Vinci kinematics at
30 Hz, 76 values a line: the left and right master tool manipulators (columns 1-19, 20-38)
and the left and right patient-side manipulators (39-57, 58-76), each a tip position (3, m),
a rotation matrix (9, row by row), linear and angular velocities (6) and the gripper angle
(1); and a meta file per task: trial, self-proclaimed experience (N, I, E), the GRS (modified
OSATS, 6-30) and its six items. This script writes

    OUT/ratings.csv                 trial,subject,experience,rating (the GRS)
    OUT/trials/TRIAL/psm-left.csv   t_s,x_m,y_m,z_m,qw,qx,qy,qz of the left tool tip
    OUT/trials/TRIAL/psm-right.csv  the right tool tip

The subject is the trial name's surgeon letter (Knot_Tying_B001: B). Needle passing is
cutlab's held-out task (docs/guide/evidence.md): the script refuses it unless --held-out is given,
so nothing is developed or tuned on it by accident.

Usage: jigsaws_to_cutlab.py KINEMATICS_DIR META_FILE OUT [--held-out]
(e.g. JIGSAWS/Knot_Tying/kinematics/AllGestures and JIGSAWS/Knot_Tying/meta_file_Knot_Tying.txt)
"""

import math
import os
import sys

LEVELS = {"N": "novice", "I": "intermediate", "E": "expert"}
TOOLS = {"psm-left": 38, "psm-right": 57}  # 0-based first column of each
RATE_HZ = 30.0


def quaternion(r):
    """A unit quaternion (w, x, y, z) of the row-major rotation matrix r (Shepperd)."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = r
    trace = m00 + m11 + m22
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = (0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = ((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = ((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s)
    n = math.sqrt(sum(c * c for c in q)) or 1.0
    return tuple(c / n for c in q)


def meta_rows(path):
    """(trial, experience, grs) of each line of a JIGSAWS meta file."""
    rows = []
    with open(path) as f:
        for line in f:
            fields = line.split()
            if len(fields) < 3:
                continue
            trial, level, grs = fields[0], fields[1], fields[2]
            if level not in LEVELS:
                raise SystemExit(f"{path}: {trial}: experience {level!r} is not N, I or E")
            rows.append((trial, LEVELS[level], float(grs)))
    return rows


def convert(kinematics, meta, out):
    os.makedirs(os.path.join(out, "trials"), exist_ok=True)
    written = []
    for trial, level, grs in meta_rows(meta):
        src = os.path.join(kinematics, trial + ".txt")
        if not os.path.exists(src):
            print(f"skipped {trial}: no {src}", file=sys.stderr)
            continue
        folder = os.path.join(out, "trials", trial)
        os.makedirs(folder, exist_ok=True)
        outs = {t: open(os.path.join(folder, t + ".csv"), "w") for t in TOOLS}
        for f in outs.values():
            f.write("t_s,x_m,y_m,z_m,qw,qx,qy,qz\n")
        with open(src) as f:
            for i, line in enumerate(f):
                v = [float(x) for x in line.split()]
                if len(v) != 76:
                    raise SystemExit(f"{src}:{i + 1}: {len(v)} values, not 76")
                for tool, c in TOOLS.items():
                    q = quaternion(v[c + 3:c + 12])
                    row = [i / RATE_HZ] + v[c:c + 3] + list(q)
                    outs[tool].write(",".join(f"{x:.6f}" for x in row) + "\n")
        for f in outs.values():
            f.close()
        subject = trial.rsplit("_", 1)[-1][0]
        written.append((trial, subject, level, grs))
    with open(os.path.join(out, "ratings.csv"), "w") as f:
        f.write("trial,subject,experience,rating\n")
        for row in written:
            f.write("%s,%s,%s,%g\n" % row)
    print(f"{len(written)} trials written to {out}")


def main(argv):
    args = [a for a in argv if not a.startswith("--")]
    if len(args) != 3:
        raise SystemExit(__doc__)
    kinematics, meta, out = args
    if "needle" in os.path.basename(meta).lower() and "--held-out" not in argv:
        raise SystemExit("needle passing is the held-out task: pass --held-out to convert it "
                         "for a final validation, never to develop or tune on it")
    convert(kinematics, meta, out)


if __name__ == "__main__":
    main(sys.argv[1:])

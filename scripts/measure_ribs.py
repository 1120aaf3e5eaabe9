#!/usr/bin/env python3
"""Rib / costal-cartilage dimensions in the TotalSegmentator example segmentation.

Reads data/totalsegmentator/example_seg.nii.gz (NIfTI-1 parsed by hand: gzip+struct),
maps voxel indices to world mm through the sform affine, and measures, for ribs 7..12 (the ones
present) and the costal cartilages, in each structure's anterior part:
  * column method: on vertical (z) columns at fixed (x, y), the run length of the label (height
    along the body axis) and the gap down to the next rib (intercostal space along the body axis);
  * cross-section method: local rib direction e1 (PCA of the label within 12 mm), outward wall
    normal n (horizontal, from the body centre of the slice), height direction h = n x e1; the
    extents of the label in a 6 mm slab across e1 along h (height) and n (thickness), voxel-
    centre extent + 3 mm. Vertical runs/gaps are also converted to perpendicular ones by |h.z|.
Usage: measure.py [--anterior MM (35)] [--radius MM (12)] [--slab MM (3)]."""
import gzip, struct, sys
import numpy as np

import os
D = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'data', 'totalsegmentator') + os.sep
def arg(name, default): return float(sys.argv[sys.argv.index(name) + 1]) if name in sys.argv else default
ANT = arg('--anterior', 35.0)   # mm from the most anterior voxel
RAD = arg('--radius', 12.0)     # PCA neighbourhood radius, mm
SLAB = arg('--slab', 3.0)       # half-thickness of the slab across the rib, mm

def load(path):
    b = gzip.open(path).read()
    assert struct.unpack('<i', b[:4])[0] == 348
    dim = struct.unpack('<8h', b[40:56]); nx, ny, nz = dim[1:4]
    dtype = struct.unpack('<h', b[70:72])[0]; assert dtype == 2  # uint8
    off = int(struct.unpack('<f', b[108:112])[0])
    sform = struct.unpack('<h', b[254:256])[0]; assert sform > 0
    A = np.eye(4); A[:3] = np.array(struct.unpack('<12f', b[280:328])).reshape(3, 4)
    a = np.frombuffer(b, np.uint8, nx * ny * nz, off).reshape(nz, ny, nx).transpose(2, 1, 0)
    return a, A

seg, A = load(D + 'example_seg.nii.gz')
fat, A2 = load(D + 'subcutaneous_fat.nii.gz'); assert np.allclose(A, A2) and fat.shape == seg.shape
VOX = abs(A[0, 0]); assert np.allclose(np.abs(np.diag(A[:3, :3])), VOX) and np.count_nonzero(A[:3, :3] - np.diag(np.diag(A[:3, :3]))) == 0
# world axes: +y anterior, +z cranial (checked: liver/cartilage anterior of autochthon; T11 above L2).
def world(ijk): return ijk @ A[:3, :3].T + A[:3, 3]

NAMES = {98 + n - 7: f'L{n}' for n in range(7, 13)}
NAMES.update({110 + n - 7: f'R{n}' for n in range(7, 13)})
NAMES[117] = 'cartilage'
nz = seg.shape[2]

# body centre per slice (x, y) from the subcutaneous-fat ring
centre = {}
for k in range(nz):
    ij = np.argwhere(fat[:, :, k] > 0)
    centre[k] = world(np.c_[ij, np.full(len(ij), k)]).mean(0)[:2]

def runs(col):
    """list of (start, end) inclusive of True runs in a 1-D bool array."""
    r, s = [], None
    for t, v in enumerate(col):
        if v and s is None: s = t
        if not v and s is not None: r.append((s, t - 1)); s = None
    if s is not None: r.append((s, len(col) - 1))
    return r

def anterior_mask(lab):
    m = seg == lab
    ijk = np.argwhere(m)
    y = world(ijk)[:, 1]
    keep = y >= y.max() - ANT
    am = np.zeros_like(m); am[tuple(ijk[keep].T)] = True
    return m, am

def cross_section(lab, am, m):
    P = world(np.argwhere(m)); C = world(np.argwhere(am)); kk = np.argwhere(am)[:, 2]
    H, T, HZ = [], [], []
    for c, k in zip(C, kk):
        near = P[np.linalg.norm(P - c, axis=1) <= RAD]
        if len(near) < 6: continue
        w, v = np.linalg.eigh(np.cov((near - near.mean(0)).T)); e1 = v[:, 2]
        n = np.r_[c[:2] - centre[k], 0.0]; n -= e1 * (n @ e1); n /= np.linalg.norm(n)
        h = np.cross(n, e1); h /= np.linalg.norm(h)
        sl = near[np.abs((near - c) @ e1) <= SLAB]
        ph, pn = (sl - c) @ h, (sl - c) @ n
        H.append(ph.max() - ph.min() + VOX); T.append(pn.max() - pn.min() + VOX); HZ.append(abs(h[2]))
    return np.array(H), np.array(T), np.array(HZ)

def columns(am, m):
    """vertical runs of the anterior part (exclude runs touching the volume's top/bottom)."""
    out, clipped = [], 0
    for i, j in {(i, j) for i, j, _ in np.argwhere(am)}:
        for s, e in runs(m[i, j, :]):
            if not am[i, j, s:e + 1].any(): continue
            if s == 0 or e == nz - 1: clipped += 1; continue
            out.append((i, j, s, e))
    return out, clipped

def binned_runs(cols, am):
    """vertical run per 3 mm bin along the anterior part's main direction (PCA), the longest run
    in each bin: columns grazing the rib's edge give short runs, the longest one in a bin is the
    run through the rib's full cross-section at that position."""
    if not cols: return np.array([np.nan])
    C = world(np.argwhere(am)); e = np.linalg.eigh(np.cov((C - C.mean(0)).T))[1][:, 2]
    e[2] = 0; e /= np.linalg.norm(e)  # horizontal direction of the rib (columns are vertical)
    best = {}
    for i, j, s_, e_ in cols:
        p = world(np.array([i, j, 0.0]))
        b = int(np.floor((p - C.mean(0)) @ e / VOX)); best[b] = max(best.get(b, 0), (e_ - s_ + 1) * VOX)
    return np.array(list(best.values()))

def axial_thickness(am, m):
    """in each axial slice, for each voxel of the anterior part: run along x and along y through it;
    the smaller of the two (the rib's extent across the wall when the rib runs along the other axis)."""
    out = []
    for i, j, k in np.argwhere(am):
        rx = [r for r in runs(m[:, j, k]) if r[0] <= i <= r[1]][0]; ry = [r for r in runs(m[i, :, k]) if r[0] <= j <= r[1]][0]
        out.append(min(rx[1] - rx[0] + 1, ry[1] - ry[0] + 1) * VOX)
    return np.array(out)

def surface_gap(a_lab, b_lab, am_a):
    """intercostal space, perpendicular: for each voxel of rib n's anterior part on its caudal
    surface (no rib-n voxel directly below), distance to the nearest voxel of rib n+1 minus one
    voxel (centre-to-centre across a gap = gap + 3 mm); kept when the nearest rib-n+1 voxel lies
    caudal (dz < 0) and within 45 mm."""
    A_ = np.argwhere(am_a); Bv = world(np.argwhere(seg == b_lab)); out = []
    for i, j, k in A_:
        if k == 0 or seg[i, j, k - 1] == a_lab: continue
        p = world(np.array([i, j, k], float)); d = np.linalg.norm(Bv - p, axis=1); q = d.argmin()
        if d[q] <= 45 and Bv[q, 2] < p[2]: out.append(d[q] - VOX)
    return np.array(out)

res = {}
print(f'affine diag {np.diag(A)[:3]}, origin {A[:3,3]}; anterior part = within {ANT} mm of the most anterior voxel')
print('label name  vox  z-range(mm)       y-max  | vert run med (n bins, clipped cols) | xsec height med  thick med  |h.z| med | vert*|h.z| | axial min(x,y) run')
for lab in sorted(NAMES):
    m, am = anterior_mask(lab)
    if not m.any(): continue
    ijk = np.argwhere(m); W = world(ijk)
    cols, clipped = columns(am, m)
    vr = binned_runs(cols, am)
    H, T, HZ = cross_section(lab, am, m); AT = axial_thickness(am, m)
    res[lab] = dict(cols=cols, am=am, m=m, hz=np.median(HZ) if len(HZ) else np.nan)
    print(f'{lab:4d} {NAMES[lab]:9s} {len(ijk):4d}  {W[:,2].min():6.1f}..{W[:,2].max():6.1f}  {W[:,1].max():6.1f} |'
          f' {np.median(vr):5.1f} ({len(vr):3d}, {clipped:2d}) iqr {np.percentile(vr,25):.0f}-{np.percentile(vr,75):.0f} |'
          f' {np.median(H):5.1f} iqr {np.percentile(H,25):.0f}-{np.percentile(H,75):.0f}  {np.median(T):5.1f} iqr {np.percentile(T,25):.0f}-{np.percentile(T,75):.0f}'
          f'  {np.median(HZ):.2f} | {np.median(vr)*np.median(HZ):5.1f} | axial-thick {np.median(AT):4.1f} (n {len(AT)})')

# intercostal spaces along the body axis: every column (anywhere along rib n) where a run of
# rib n lies directly above a run of rib n+1 with no other rib or cartilage between; y range of
# those columns shown so one can see how anterior they are.
print('\nspaces along z (vertical gap, bottom of rib n to top of rib n+1, same column; all columns of rib n)')
ribset = set(range(98, 116)) | {117}
for side, base in (('L', 98), ('R', 110)):
    for n in range(7, 12):
        a_lab, b_lab = base + n - 7, base + n - 6
        gaps, ys = [], []
        for i, j in {tuple(x) for x in np.argwhere((seg == a_lab).any(2))}:
            col = seg[i, j, :]
            for s_, e_ in runs(col == a_lab):
                below = [t for t in range(s_ - 1, -1, -1) if col[t] in ribset]
                if below and col[below[0]] == b_lab:
                    gaps.append((s_ - below[0] - 1) * VOX); ys.append(world(np.array([i, j, 0.0]))[1])
        if gaps:
            g = np.array(gaps); hz = np.nanmean([res[a_lab]['hz'], res[b_lab]['hz']])
            print(f'  {side}{n}-{side}{n+1}: median {np.median(g):5.1f} mm (n {len(g):3d}, iqr {np.percentile(g,25):.0f}-{np.percentile(g,75):.0f}),'
                  f' columns at y {min(ys):.0f}..{max(ys):.0f}; x|h.z| {hz:.2f} -> {np.median(g)*hz:5.1f} mm perpendicular')
        else:
            print(f'  {side}{n}-{side}{n+1}: no column has rib {n+1} directly below rib {n}')

print('\nspaces, perpendicular (caudal surface of rib n anterior part -> nearest voxel of rib n+1, minus 3 mm)')
for side, base in (('L', 98), ('R', 110)):
    for n in range(7, 12):
        a_lab, b_lab = base + n - 7, base + n - 6
        if a_lab not in res: continue
        g = surface_gap(a_lab, b_lab, res[a_lab]['am'])
        if len(g): print(f'  {side}{n}-{side}{n+1}: median {np.median(g):5.1f} mm  iqr {np.percentile(g,25):.1f}-{np.percentile(g,75):.1f}  (n {len(g)})')
        else: print(f'  {side}{n}-{side}{n+1}: none')

# rib order check: in shared columns, rib n+1 should be below rib n
print('\norder check (all columns holding both ribs n and n+1): fraction with n+1 below n')
for side, base in (('L', 98), ('R', 110)):
    for n in range(7, 12):
        a, b = base + n - 7, base + n - 6
        ok = tot = 0
        for i, j in {tuple(x) for x in np.argwhere((seg == a).any(2) & (seg == b).any(2))}:
            za = np.where(seg[i, j] == a)[0].mean(); zb = np.where(seg[i, j] == b)[0].mean(); tot += 1; ok += zb < za
        print(f'  {side}{n}/{side}{n+1}: {ok}/{tot}', end='')
    print()
print('\nside check: centroid x of rib_left_* labels', round(world(np.argwhere((seg >= 98) & (seg <= 103)))[:, 0].mean(), 1),
      ' rib_right_*', round(world(np.argwhere((seg >= 110) & (seg <= 115)))[:, 0].mean(), 1),
      ' spleen', round(world(np.argwhere(seg == 1))[:, 0].mean(), 1), ' liver', round(world(np.argwhere(seg == 5))[:, 0].mean(), 1))
print('sternum (116) voxels:', int((seg == 116).sum()), ' labels 92-97/104-109 (ribs 1-6):', int(((seg >= 92) & (seg <= 97)).sum() + ((seg >= 104) & (seg <= 109)).sum()))

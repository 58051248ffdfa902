# bake vs service bit-for-bit, for the same stage
import sys, numpy as np
from pxr import Usd, UsdGeom
from cli import *
stage, baked = sys.argv[1], sys.argv[2]
req, pools, pts = load(stage)
bid = bind(req)['binding_id']
st = Usd.Stage.Open(stage); bk = Usd.Stage.Open(baked)
mesh = [p for p in st.Traverse() if p.IsA(UsdGeom.Mesh) and p.GetRelationship('curvenet:curvenets')][0]
cns = [st.GetPrimAtPath(t) for t in mesh.GetRelationship('curvenet:curvenets').GetTargets()]
bm = bk.GetPrimAtPath(mesh.GetPath()).GetAttribute('points')
frames = []; ts = list(range(int(st.GetStartTimeCode()), int(st.GetEndTimeCode())+1))
for t in ts:
    frames.append({'posed': [np.array(c.GetAttribute('primvars:curvenet:cv').Get(t), dtype=np.float32) for c in cns]})
s, r = batch_bin(bid, frames)
ok = 0
for i, t in enumerate(ts):
    want = np.array(bm.Get(t), dtype=np.float32)
    got = r[1][i]['points']
    if want.tobytes() == got.tobytes(): ok += 1
    else: print('frame', t, 'maxdiff', np.abs(want.astype(float)-got).max())
print(stage, 'equal', ok, '/', len(ts))

"""The instance-box test of the two-level traversal (instance_traversal._misses_box), on and off in one
process: a scatter of N grid meshes (288 triangles, random rotations and scales, 1 apart), 480x270
camera rays from above at an angle and as many short occlusion rays; "no skip" gives every instance a
box every ray meets, so the same compiled kernel clips and always enters. Alternating, medians of 7,
hits checked identical. Usage: python benchmarks/bench_instance_boxes.py [N=200000]
"""
import sys, time
from pathlib import Path
import numpy as np
sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
import core
from core.scene.scene_builder import SceneBuilder, MeshInput
from core.jit.first_frame import grid_mesh
n = int(sys.argv[1]) if len(sys.argv) > 1 else 200000
v,t=grid_mesh(12)
rng=np.random.default_rng(0)
side=int(np.ceil(np.sqrt(n)))
q,_=np.linalg.qr(rng.normal(size=(n,3,3)))
m=np.zeros((n,4,4)); m[:,:3,:3]=q*rng.uniform(0.2,0.45,n)[:,None,None]
m[:,0,3]=np.arange(n)%side; m[:,1,3]=np.arange(n)//side; m[:,3,3]=1
scene,_=SceneBuilder().build([MeshInput('g',v,t,1)], np.zeros(n,np.int64), m)
# camera rays from above at an angle over the whole scatter, and random short AO-like rays
W,H=480,270
xs,ys=np.meshgrid(np.linspace(0,side,W),np.linspace(0,side,H))
o=np.stack([np.full(W*H,side/2),np.full(W*H,-side*0.55),np.full(W*H,side*0.45)],1)
target=np.stack([xs.ravel(),ys.ravel(),np.zeros(W*H)],1)
d=target-o; d/=np.linalg.norm(d,axis=1,keepdims=True)
ao_o=target+np.array([0,0,0.5]); ao_d=rng.normal(size=(W*H,3)); ao_d[:,2]=np.abs(ao_d[:,2]); ao_d/=np.linalg.norm(ao_d,axis=1,keepdims=True)
real=scene.world_boxes.copy()
huge=np.tile(np.array([-1e30,-1e30,-1e30,1e30,1e30,1e30],np.float32),(n,1))
def run():
    a=core.intersect_scene(scene,o,d); b=core.occluded_scene(scene,ao_o,ao_d,tmax=1.0); return a,b
ref=None; res={'box test':[], 'no skip':[]}
for rep in range(8):
    for name,boxes in (('box test',real),('no skip',huge)):
        scene.world_boxes[:]=boxes
        t0=time.perf_counter(); a,b=run(); dt=time.perf_counter()-t0
        if rep: res[name].append(dt)
        if ref is None: ref=(a,b)
        else: assert np.array_equal(a.prim,ref[0].prim) and np.array_equal(a.t,ref[0].t) and np.array_equal(b,ref[1])
for k,vv in res.items(): print(k, round(np.median(vv)*1e3,1),'ms')
print('ratio', np.median(res['box test'])/np.median(res['no skip']))

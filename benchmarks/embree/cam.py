# Prints Embree viewer camera flags that frame the dragon as sray's default
# mesh view does (engine/src/scene/setup.rs, default_view): the dragon's
# bounding box, 20 degrees up, 25 degrees around, 40 degree field of view.
import math
lo=[-0.108324, 0.0527295, -0.0504143]; hi=[0.0965662, 0.197173, 0.0412075]
def add(a,b): return [x+y for x,y in zip(a,b)]
def sub(a,b): return [x-y for x,y in zip(a,b)]
def sc(a,s): return [x*s for x in a]
def dot(a,b): return sum(x*y for x,y in zip(a,b))
def cross(a,b): return [a[1]*b[2]-a[2]*b[1], a[2]*b[0]-a[0]*b[2], a[0]*b[1]-a[1]*b[0]]
def unit(a): n=math.sqrt(dot(a,a)); return sc(a,1/n)
at=sc(add(lo,hi),0.5); up=[0,1,0]; fr=[0,0,1]; fov=40.0
right=unit(cross(sc(fr,-1),up)); el,az=math.radians(20),math.radians(25)
d=unit(add(sc(add(sc(fr,math.cos(az)),sc(right,math.sin(az))),math.cos(el)),sc(up,math.sin(el))))
fwd=sc(d,-1); r=unit(cross(fwd,up)); u=cross(r,fwd)
t=math.tan(math.radians(fov)/2)*0.9; tx=ty=t
dist=0
for k in range(8):
    c=[lo[0] if k&1==0 else hi[0], lo[1] if k&2==0 else hi[1], lo[2] if k&4==0 else hi[2]]
    o=sub(c,at); x,y,z=dot(o,r),dot(o,u),dot(o,d)
    dist=max(dist,z+abs(x)/tx,z+abs(y)/ty)
frm=add(at,sc(d,dist))
print('--vp %.7g %.7g %.7g --vi %.7g %.7g %.7g --vu 0 1 0 --fov 40' % (*frm,*at))

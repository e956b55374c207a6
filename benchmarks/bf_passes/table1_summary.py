import collections,statistics
d=collections.defaultdict(list)
for l in open('table1_runs.txt'):
    p=l.split()
    if len(p)<6: print(l); continue
    s,t,b,m,i,tt=p[:6]; d[(s,t,b,m)].append(float(tt))
for t in '12':
  print(f"threads {t}: scene oldDF newDF newBF oldBF  newBF/oldDF newBF/newDF oldBF/oldDF")
  for s in "balls gears mount rings tetra tree teapot".split():
    od,nd,nb,ob=[statistics.median(d[(s,t,b,m)]) for b,m in [("OLD","df"),("NEW","df"),("NEW","bf"),("OLD","bf")]]
    print(f"  {s} {od:.3f} {nd:.3f} {nb:.3f} {ob:.3f}  {nb/od:.2f} {nb/nd:.2f} {ob/od:.2f}")
for s in "balls gears mount rings tetra tree teapot".split():
    a=statistics.median(d[(s,'1','NEW','bf')]); b=statistics.median(d[(s,'2','NEW','bf')]); a0=statistics.median(d[(s,'1','OLD','bf')]); b0=statistics.median(d[(s,'2','OLD','bf')]); print(s,'bf 2T speedup new', round(a/b,2), 'old', round(a0/b0,2))

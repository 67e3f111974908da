#!/usr/bin/env python3
"""The file-level import graph of one crate: its circles, and the arrows
that go from a lower layer up.

    python3 tools/import-graph.py CRATE_DIR [LAYERS]

LAYERS is the crate's top-level modules from the bottom up, comma-separated
(lib.rs lists them). An arrow is a `crate::`, `super::` or `self::` path, or
a path into a child module, from one file to the file that defines what it
names: a name re-exported by a `mod.rs` (or `lib.rs`) resolves to the file
that defines it, and `pub use` lines, `mod` lines, comments and test modules
are no arrows. Prints `no circles` or each circle with its arrows, then,
with LAYERS, the arrows from a lower layer up.
"""
import os, re, sys
if len(sys.argv) < 2:
    sys.exit(__doc__)
root=sys.argv[1]; src=os.path.join(root,'src')
files={}
for d,_,fs in os.walk(src):
    for fn in fs:
        if fn.endswith('.rs'):
            f=os.path.join(d,fn)
            rel=os.path.relpath(f,src)[:-3].split(os.sep)
            if rel[-1] in ('mod',): rel=rel[:-1]
            if rel==['lib'] or rel==['main']: rel=[]
            files[tuple(rel)]=os.path.relpath(f,root)
REEXPORT={}  # (module, name) -> defining module path
def resolve(segs, seen=0):
    segs=tuple(segs)
    for n in range(len(segs),-1,-1):
        if segs[:n] in files:
            m=segs[:n]
            if n<len(segs) and (m,segs[n]) in REEXPORT and seen<10:
                return resolve(REEXPORT[(m,segs[n])]+(segs[n],), seen+1)
            return m
    return None
def paths_in(text):
    out=[]
    for m in re.finditer(r'\b(crate|super|self)((?:::(?:[A-Za-z_][A-Za-z0-9_]*|\{))+)',text):
        kind=m.group(1); rest=m.group(2)
        if rest.endswith('{'):
            j=m.end(); lvl=1; k=j
            while lvl and k<len(text):
                if text[k]=='{': lvl+=1
                elif text[k]=='}': lvl-=1
                k+=1
            inner=text[j:k-1]; base=[s for s in rest.split('::') if s and s!='{']
            lvl=0; tok=''; names=[]
            for ch in inner:
                if ch=='{': lvl+=1
                elif ch=='}': lvl-=1
                if lvl==0 and ch==',': names.append(tok); tok=''
                else: tok+=ch
            names.append(tok)
            for n in names:
                n=n.strip()
                if not n: continue
                segs=[s for s in re.split(r'::',n.split('{')[0]) if s]
                out.append((kind,base+segs))
        else:
            out.append((kind,[s for s in rest.split('::') if s]))
    return out
import collections
CHILDREN=collections.defaultdict(set)
for me in files:
    if me: CHILDREN[me[:-1]].add(me[-1])
# re-exports: `pub use a::b::{X, Y};` and `pub use a::b::X;` in any module file
for me,f in files.items():
    text=open(os.path.join(root,f)).read()
    isdir=f.endswith('mod.rs') or f.endswith('lib.rs') or f.endswith('main.rs')
    for m in re.finditer(r'pub(?:\([a-z]+\))? use ((?:crate|super|self)?(?:::)?[A-Za-z_][A-Za-z0-9_:]*?)::(\{[^;]*\}|[A-Za-z_][A-Za-z0-9_]*);',text,re.S):
        path=[p for p in m.group(1).split('::') if p]
        names=m.group(2)
        names=[n.strip().split(' as ')[0] for n in names.strip('{}').split(',') if n.strip() and '::' not in n and '{' not in n]
        if path and path[0]=='crate': base=path[1:]
        elif path and path[0] in ('super','self'):
            base=list(me if isdir else me[:-1])
            while path and path[0]=='super': base=base[:-1]; path=path[1:]
            if path and path[0]=='self': path=path[1:]
            base=base+path
        else:
            base=list(me if isdir else me[:-1])+path
        for n in names:
            REEXPORT[(me,n)]=tuple(base)
E={}
for me,f in files.items():
    text=open(os.path.join(root,f)).read()
    text=re.split(r'#\[cfg\(test\)\]\s*(?:pub\(crate\) )?mod tests',text)[0]
    text=re.sub(r'//[^\n]*','',text)
    isdir=f.endswith('mod.rs') or f.endswith('lib.rs') or f.endswith('main.rs')
    # re-export lines themselves are no arrows
    body=re.sub(r'pub(?:\([a-z]+\))? use [^;]*;','',text)
    refs=paths_in(body)
    # bare paths into child modules (`vertex::ALGORITHM_VERSION` in
    # method/mod.rs)
    if isdir:
        for ch in CHILDREN[me]:
            for m in re.finditer(r'(?<![:A-Za-z0-9_])'+ch+r'::([A-Za-z_][A-Za-z0-9_]*(?:::[A-Za-z_][A-Za-z0-9_]*)*|\{)',body):
                rest=m.group(1)
                refs.append(('self',[ch]+([p for p in rest.split('::') if p] if rest!='{' else [])))
    for kind,segs in refs:
        if kind=='crate': t=segs
        elif kind=='self': t=list(me)+segs
        else:
            base=list(me[:-1]); s=segs
            while s and s[0]=='super': base=base[:-1]; s=s[1:]
            t=base+s
        r=resolve(t)
        if r is None or r==me: continue
        if r==(): continue  # lib.rs re-exports count as none
        E.setdefault(me,set()).add(r)
idx={}; low={}; st=[]; on=set(); sccs=[]; c=[0]
sys.setrecursionlimit(100000)
def sc(v):
    idx[v]=low[v]=c[0]; c[0]+=1; st.append(v); on.add(v)
    for w in E.get(v,()):
        if w not in idx: sc(w); low[v]=min(low[v],low[w])
        elif w in on: low[v]=min(low[v],idx[w])
    if low[v]==idx[v]:
        comp=[]
        while True:
            w=st.pop(); on.discard(w); comp.append(w)
            if w==v: break
        if len(comp)>1: sccs.append(comp)
for v in sorted(files):
    if v not in idx: sc(v)
for s in sccs:
    print('circle:',' '.join(sorted(files[x] for x in s)))
    for a in s:
        for b in E.get(a,()):
            if b in s: print('   ',files[a],'->',files[b])
if not sccs: print('no circles')
if len(sys.argv)>2:
    order=sys.argv[2].split(',')
    rank={m:i for i,m in enumerate(order)}
    up=[]
    for a,bs in E.items():
        for b in bs:
            ta=a[0] if a else ''; tb=b[0] if b else ''
            if ta in rank and tb in rank and rank[tb]>rank[ta]:
                up.append((files[a],files[b]))
    print('upward arrows:',len(up))
    for x in sorted(up): print('   ',x[0],'->',x[1])
    missing=sorted({(a[0] if a else '') for a in files} - set(rank) - {''})
    if missing: print('unranked:',missing)

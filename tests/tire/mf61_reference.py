#!/usr/bin/env python3
"""An evaluation of the Magic Formula 6.1 written apart from vdyn's C++ law, from the published
equations (Pacejka, Tire and Vehicle Dynamics, 3rd ed. 2012, 4.E1-4.E78) in the forms of TNO's solver
that MFeval documents (docs/model.md 8.2b lists them), steady state, no turn slip. It writes
mf61_reference.csv, the table test_tire's MagicFormula.AgreesWithAnEvaluationWrittenApart compares
the law with: loads, pressures, inclinations and combined slips the closed-form tests do not reach.

    python3 tests/tire/mf61_reference.py tires/vdyn_synthetic_205_55R16_mf61.tir > tests/tire/mf61_reference.csv
"""
import itertools
import math
import re
import sys


def read(path):
    """KEY = value lines of a .tir file in SI units (the synthetic file's), comments after $."""
    c = {}
    for line in open(path):
        m = re.match(r"([A-Za-z_0-9]+)\s*=\s*(.+)", line.split("$")[0].strip())
        if m:
            try:
                c[m.group(1).upper()] = float(m.group(2))
            except ValueError:
                pass
    return c


def sgn(x): return 1.0 if x>=0 else -1.0
def mf(c,Fz,kappa,alpha,gamma=0.0,p=None,Vx=None):
    g=lambda k: c.get(k,0.0)
    if p is None: p=g('NOMPRES')
    if Vx is None: Vx=g('LONGVL')
    Fz0=g('FNOMIN'); Fz0p=Fz0*g('LFZO'); dfz=(Fz-Fz0p)/Fz0p; dpi=(p-g('NOMPRES'))/g('NOMPRES')
    a=math.tan(alpha); gs=math.sin(gamma); eps=1e-6
    Vc=Vx/math.cos(alpha); cosap=Vx/(Vc+eps)
    lmux=g('LMUX'); lmuy=g('LMUY')
    # Fx0
    Cx=g('PCX1')*g('LCX'); mux=(g('PDX1')+g('PDX2')*dfz)*(1+g('PPX3')*dpi+g('PPX4')*dpi**2)*(1-g('PDX3')*gamma**2)*lmux
    Dx=mux*Fz; Kxk=Fz*(g('PKX1')+g('PKX2')*dfz)*math.exp(g('PKX3')*dfz)*(1+g('PPX1')*dpi+g('PPX2')*dpi**2)*g('LKX')
    Bx=Kxk/(Cx*Dx+eps); SHx=(g('PHX1')+g('PHX2')*dfz)*g('LHX'); SVx=Fz*(g('PVX1')+g('PVX2')*dfz)*g('LVX')*lmux
    kx=kappa+SHx; Ex=min((g('PEX1')+g('PEX2')*dfz+g('PEX3')*dfz**2)*(1-g('PEX4')*sgn(kx))*g('LEX'),1)
    Fx0=Dx*math.sin(Cx*math.atan(Bx*kx-Ex*(Bx*kx-math.atan(Bx*kx))))+SVx
    # Fy0
    def fy0(gs):
        Kya=g('PKY1')*Fz0p*(1+g('PPY1')*dpi)*(1-g('PKY3')*abs(gs))*math.sin(g('PKY4')*math.atan(Fz/Fz0p/((g('PKY2')+g('PKY5')*gs**2)*(1+g('PPY2')*dpi))))*g('LKY')
        SVyg=Fz*(g('PVY3')+g('PVY4')*dfz)*gs*g('LKYC')*lmuy
        Kyg0=Fz*(g('PKY6')+g('PKY7')*dfz)*(1+g('PPY5')*dpi)*g('LKYC')
        SHy=(g('PHY1')+g('PHY2')*dfz)*g('LHY')+(Kyg0*gs-SVyg)/(Kya+eps*sgn(Kya))
        SVy=Fz*(g('PVY1')+g('PVY2')*dfz)*g('LVY')*lmuy+SVyg
        ay=a+SHy; Cy=g('PCY1')*g('LCY')
        muy=(g('PDY1')+g('PDY2')*dfz)*(1+g('PPY3')*dpi+g('PPY4')*dpi**2)*(1-g('PDY3')*gs**2)*lmuy
        Dy=muy*Fz; Ey=min((g('PEY1')+g('PEY2')*dfz)*(1+g('PEY5')*gs**2-(g('PEY3')+g('PEY4')*gs)*sgn(ay))*g('LEY'),1)
        By=Kya/(Cy*Dy+eps*sgn(Dy))
        return dict(Fy0=Dy*math.sin(Cy*math.atan(By*ay-Ey*(By*ay-math.atan(By*ay))))+SVy,Kya=Kya,SHy=SHy,SVy=SVy,By=By,Cy=Cy,muy=muy)
    y=fy0(gs); y0=fy0(0.0)
    # combined
    G=lambda B,C,E,x: math.cos(C*math.atan(B*x-E*(B*x-math.atan(B*x))))
    Exa=min(g('REX1')+g('REX2')*dfz,1); Bxa=(g('RBX1')+g('RBX3')*gs**2)*math.cos(math.atan(g('RBX2')*kappa))*g('LXAL')
    Gxa=G(Bxa,g('RCX1'),Exa,a+g('RHX1'))/G(Bxa,g('RCX1'),Exa,g('RHX1')); Fx=Gxa*Fx0
    DVyk=y['muy']*Fz*(g('RVY1')+g('RVY2')*dfz+g('RVY3')*gs)*math.cos(math.atan(g('RVY4')*a))
    SVyk=DVyk*math.sin(g('RVY5')*math.atan(g('RVY6')*kappa))*g('LVYKA')
    SHyk=g('RHY1')+g('RHY2')*dfz; Eyk=min(g('REY1')+g('REY2')*dfz,1)
    Byk=(g('RBY1')+g('RBY4')*gs**2)*math.cos(math.atan(g('RBY2')*(a-g('RBY3'))))*g('LYKA')
    Gyk=G(Byk,g('RCY1'),Eyk,kappa+SHyk)/G(Byk,g('RCY1'),Eyk,SHyk); Fy=Gyk*y['Fy0']+SVyk
    # Mz
    R0=g('UNLOADED_RADIUS'); Kyap=y['Kya']+eps*sgn(y['Kya'])
    ar=a+y['SHy']+y['SVy']/Kyap; SHt=g('QHZ1')+g('QHZ2')*dfz+(g('QHZ3')+g('QHZ4')*dfz)*gs; at=a+SHt
    Bt=(g('QBZ1')+g('QBZ2')*dfz+g('QBZ3')*dfz**2)*(1+g('QBZ4')*gamma+g('QBZ5')*abs(gamma))*g('LKY')/lmuy
    Ct=g('QCZ1'); Dt=(g('QDZ1')+g('QDZ2')*dfz)*(1-g('PPZ1')*dpi)*(1+g('QDZ3')*gamma+g('QDZ4')*gamma**2)*Fz*(R0/Fz0p)*g('LTR')
    Et=min((g('QEZ1')+g('QEZ2')*dfz+g('QEZ3')*dfz**2)*(1+(g('QEZ4')+g('QEZ5')*gs)*(2/math.pi)*math.atan(Bt*Ct*at)),1)
    Br=g('QBZ9')*g('LKY')/lmuy+g('QBZ10')*y['By']*y['Cy']
    Dr=Fz*R0*((g('QDZ6')+g('QDZ7')*dfz)*g('LRES')+((g('QDZ8')+g('QDZ9')*dfz)*(1+g('PPZ2')*dpi)+(g('QDZ10')+g('QDZ11')*dfz)*abs(gs))*gs*g('LKZC'))*lmuy*sgn(Vx)*math.cos(a)
    kr=(Kxk/Kyap)**2*kappa**2
    areq=math.atan(math.sqrt(math.tan(ar)**2+kr))*sgn(ar); ateq=math.atan(math.sqrt(math.tan(at)**2+kr))*sgn(at)
    s=R0*(g('SSZ1')+g('SSZ2')*Fy/Fz0+(g('SSZ3')+g('SSZ4')*dfz)*gamma)*g('LS')
    Mzr=Dr*math.cos(math.atan(Br*areq)); t=Dt*G(Bt,Ct,Et,ateq)*cosap*g('LFZO')
    Mz=-t*Gyk*y0['Fy0']+Mzr+s*Fx
    return dict(Fx=Fx,Fy=Fy,Mz=Mz,t=t,Mzr=Mzr,Kya=y['Kya'],Kxk=Kxk)


def main():
    c = read(sys.argv[1])
    print("Fz_N,pressure_Pa,gamma_rad,kappa,alpha_rad,Fx_N,Fy_N,Mz_Nm")
    for Fz, p, gamma, kappa, alpha in itertools.product(
            [1500.0, 4500.0, 8000.0], [180e3, 290e3], [-0.1, 0.0, 0.08],
            [-0.5, -0.02, 0.0, 0.05, 0.6], [-0.3, -0.01, 0.0, 0.04, 0.4]):
        o = mf(c, Fz, kappa, alpha, gamma, p)
        print("%.17g,%.17g,%.17g,%.17g,%.17g,%.12g,%.12g,%.12g" % (Fz, p, gamma, kappa, alpha, o["Fx"], o["Fy"], o["Mz"]))


if __name__ == "__main__":
    main()

"""Reference intensity measures of the shipped El Centro 1940 N-S record, computed without nscd.

Run once by hand (``python tests/reference/elcentro_intensity.py``); its printout is
pasted into ``tests/test_intensity.py`` as the expected values. It reads the AT2 file
with its own few lines of parsing and applies the textbook definitions with numpy and
scipy (trapezoidal rule over the samples, the convention of PEER, gmprocess, eqsig and
SeismoSignal), and asks eqsig (an independent package) for the values it computes.
"""
from pathlib import Path

import numpy as np
from scipy.integrate import cumulative_trapezoid

G = 9.80665   # standard gravity, m/s^2
AT2 = Path(__file__).resolve().parents[2] / "nscd" / "data" / "elcentro_1940_ns.AT2"

lines = AT2.read_text().splitlines()
npts = int(lines[3].split("NPTS=")[1].split(",")[0])
dt = float(lines[3].split("DT=")[1].split()[0])
acc = np.array(" ".join(lines[4:]).split(), dtype=float)[:npts] * G     # file unit: g
t = np.arange(npts) * dt

# --- textbook definitions, trapezoid over the samples
husid = cumulative_trapezoid(acc**2, dx=dt, initial=0.0)
arias = np.pi / (2 * G) * husid[-1]
t5, t10, t90, t95 = np.interp(np.array([0.05, 0.10, 0.90, 0.95]) * husid[-1], husid, t)
vel = cumulative_trapezoid(acc, dx=dt, initial=0.0)
disp = cumulative_trapezoid(vel, dx=dt, initial=0.0)
d80 = t90 - t10
a_rms = np.sqrt(np.trapezoid(acc[(t >= t10) & (t <= t90)] ** 2, dx=dt) / d80)  # samples inside [t10, t90]
a_rms_exact80 = np.sqrt(0.8 * husid[-1] / d80)
print(f"npts={npts} dt={dt}")
print(f"PGA      {np.max(np.abs(acc)):.10g} m/s^2")
print(f"PGV      {np.max(np.abs(vel)):.10g} m/s")
print(f"PGD      {np.max(np.abs(disp)):.10g} m")
print(f"arias    {arias:.10g} m/s")
print(f"D5_95    {t95 - t5:.10g} s")
print(f"D10_90   {d80:.10g} s")
print(f"a_rms    {a_rms_exact80:.10g} m/s^2 (sqrt(0.8 I / D80)); over the samples in [t10, t90]: {a_rms:.10g}")
print(f"Ic       {a_rms_exact80**1.5 * d80**0.5:.10g}")

# --- eqsig (pip package, independent implementation)
import eqsig
asig = eqsig.AccSignal(acc, dt)
ai = eqsig.im.calc_arias_intensity(asig)[-1]
print(f"eqsig arias (g = 9.81)        {ai:.10g}  x 9.81/9.80665 = {ai * 9.81 / G:.10g}")
print(f"eqsig D5_95 (sample-resolved) {eqsig.im.calc_sig_dur(asig):.10g}")
print(f"eqsig PGV                     {np.max(np.abs(asig.velocity)):.10g}")
print(f"eqsig PGD                     {np.max(np.abs(asig.displacement)):.10g}")

# --- exact integral of the square of the piecewise-linear interpolant, by brute force:
# 1000 sub-samples per step, trapezoid (error ~ (dt/1000)^2 relative, far below 1e-6)
fine_t = np.linspace(0.0, t[-1], 1000 * (npts - 1) + 1)
fine_a = np.interp(fine_t, t, acc)
print(f"arias of the interpolant (1000x refined trapezoid) {np.pi / (2 * G) * np.trapezoid(fine_a**2, fine_t):.10g}")

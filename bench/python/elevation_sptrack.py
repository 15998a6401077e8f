"""sonoflow against PyMUST 0.1.9, one thread each, same process: SIMUS and PFIELD with points off
the imaging plane (MUST's elevation model) and speckle tracking (sptrack). BENCHMARKS.md §13.
Run: OPENBLAS_NUM_THREADS=1 python bench/python/elevation_sptrack.py"""
import numpy as np, pymust, sonoflow as sf, copy, time, scipy.ndimage as nd
sf.set_threads(1)
rng = np.random.default_rng(2)
P = pymust.getparam("L11-5v")
n = 500
x = rng.uniform(-8e-3, 8e-3, n); z = rng.uniform(5e-3, 30e-3, n); y = rng.uniform(-2e-3, 2e-3, n); rc = rng.rayleigh(1, n)
d = pymust.txdelay(P, 0.0)
def best(f, k=3):
    t = []
    for _ in range(k):
        t0 = time.perf_counter(); f(); t.append(time.perf_counter() - t0)
    return min(t)
tp = best(lambda: pymust.simus(x, y, z, rc, d, copy.deepcopy(P)), 2)
ts = best(lambda: sf.simus(x, y, z, rc, d, copy.deepcopy(P)), 2)
t2 = best(lambda: sf.simus(x, z, rc, d, copy.deepcopy(P)), 2)
print(f"simus 3-D {n} scatterers L11-5v: PyMUST {tp:.2f} s, sonoflow {ts:.2f} s ({tp/ts:.1f}x); sonoflow 2-D {t2:.3f} s")
X, Z = np.meshgrid(np.linspace(-0.01, 0.01, 60), np.linspace(0.002, 0.04, 60)); Y = np.full(X.shape, 1e-3)
tp = best(lambda: pymust.pfield(X, Y, Z, d, copy.deepcopy(P)))
ts = best(lambda: sf.pfield(X, Y, Z, d, copy.deepcopy(P)))
print(f"pfield 3-D 60x60: PyMUST {tp:.2f} s, sonoflow {ts:.2f} s ({tp/ts:.1f}x)")
base = nd.gaussian_filter(rng.standard_normal((296, 296)), 2.0, mode="wrap")
F = np.fft.fft2(base); sh = np.real(np.fft.ifft2(nd.fourier_shift(F, (1.3, -0.7))))
I = np.stack([base[20:-20, 20:-20], sh[20:-20, 20:-20]], axis=2)
Pm = pymust.utils.Param(); Pm.winsize = np.array([[32, 32], [16, 16]])
tp = best(lambda: pymust.sptrack(I, copy.deepcopy(Pm)))
ts = best(lambda: sf.sptrack(I, {"winsize": [[32, 32], [16, 16]]}))
print(f"sptrack 256x256, 2 images, windows 32->16, overlap 50%: PyMUST {tp:.3f} s, sonoflow {ts:.3f} s ({tp/ts:.1f}x)")

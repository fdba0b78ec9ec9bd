import sys
import numpy as np
from scipy.stats import chi2
sys.path.insert(0, '/work/wt/core/scratch')
from gen import *
t, w, y, m, noise = record(crank(5.0), 3.0, offset=5e-9, noise=0.2e-9)
print('y first', y[:5], 'std first 900', np.std(y[:900]), 'noise', noise)
print('w first', w[:3], w[900:905])
N=200
buf = y[300:500]
print('energy', ((buf-buf.mean())**2).sum()/noise**2, 'thr', chi2.ppf(0.999, N-1))

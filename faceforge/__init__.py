"""faceforge: anatomical facial animation with position-based dynamics.

Implements Fratarcangeli, *Position-based facial animation synthesis* (2012):
a template skull with a 3-DOF jaw and a layered muscle map is fitted into any
head mesh, the skin is bound to muscles and bone, and MPEG-4 FAP tracks drive
muscle contractions simulated with position-based dynamics.

Importing this package is cheap: heavy dependencies (numba, trimesh) are
imported by the submodules that need them.
"""

__version__ = "0.1.0"

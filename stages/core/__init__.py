"""The ground floor: science more than one stage needs, one sub-package per subject.

``geometry``  capsules and the SAH BVH over capsule chains (ray queries on explicit fibres)
``curves``    yarn centre curves: Hermite splines, arc length, rotation-minimising frames, closest
              points, seed 000's yarn space, woven centrelines from an interlacement matrix
``yarn``      the procedural yarn model (seed 000): parameter layout, fibres, loops and hairs, the
              tables' layout, their derived acceleration and the point lookups
``shading``   scattering models with one eval / pdf / sample interface: the fibre BCSDF, Lambert,
              the SGGX micro-flake phase function, and the packed material rows that select them
``shell``     shell-mapped tiled exemplars (seed 001 §5.1): the scene and its ray traversal
``sh``        real spherical harmonics: evaluation, quadrature, projection, exact rotation matrices
``sg``        spherical Gaussians: mass, products, Fibonacci axes, their SH (zonal) expansion table
``rng``       counter-based random numbers (thread-count independent)
``inline_copy`` numba's inliner copying an inlined function's IR with one scope copy (compile time only)

Nothing here imports a stage package; stage packages import from here.
"""

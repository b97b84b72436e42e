"""The render methods' integrators, one per method, each overloading ``stages.render.integrator.radiance``
for its integrator tuple class (the skeleton's tile loop calls it):

``fiberpath``  explicit fibre surfaces (realized or shell-mapped), BCSDF or Lambert materials
``volpath``    micro-flake media by delta / ratio tracking (``stages.render.media``)
``prt``        precomputed fabric transport of Khungurn et al. 2017 (SVF and IIRTF on shell-mapped exemplars)
``btf``        fitted cloth textures of Daubert et al. 2001 on a base surface
``bysdf``      the multi-scale yarn model: yarn tubes, implicit plies and the BYSDF
"""

"""The procedural yarn model of seed 000 and its point lookups.

``model``          packed yarn-type parameters (layout and indices) and the fibre model: regular
                   fibres, migration, loops, hairs, and the bounds the lookups rely on
``hair_free``      the hair quad-tree shared by the hybrid tables and the realization-free lookups
``tables``         the ``Tables`` layout (stored and derived fields) and the windows both the tables
                   build and the lookups compute
``frame_samples``  sampled yarn frames, coarse chords and the chord grid (step 1 of Algorithm 1)
``accel``          the derived lookup acceleration, rebuilt whenever tables are loaded
``fibre_tests``    closest points and exact coverage tests of one regular fibre or hair
``lookup``         Algorithm 1: which fibre covers a point, in which yarn
``implicit_plies`` seed 004 §3.3: the first ply of the model a ray meets inside a yarn (bysdf)
``implicit_tables`` seed 004 §3.4: the fibre and shadowing tables' layout and lookups, the fibre frame
"""

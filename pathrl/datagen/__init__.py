"""Dataset generation, above the baselines it uses (TOPP-RA times the TrueAdapt trajectories): ``pathrl-dataset
generate`` (:func:`pathrl.datagen.generate.generate_dataset`) dispatches to the generators registered in
:mod:`pathrl.datagen.generators` (random, target point, ball balancing paths; :mod:`pathrl.datagen.trueadapt`
trajectories). The datasets they write are read by :mod:`pathrl.dataset`."""

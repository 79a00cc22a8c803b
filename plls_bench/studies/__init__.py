"""The paper's MountainCar latent-space studies (Figs 7-9, Sec. 5.1): the ``study`` runner
(latent_space.py), the measures it reports (measures.py) and the car driven from a chosen state
(mountaincar.py).

Layer ``analyses`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``learners``); no layer below imports it.
"""

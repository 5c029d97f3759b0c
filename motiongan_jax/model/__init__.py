"""The model: G, D and the Latent Transform built from a config's model section (`build`), and the one
small API every user of a trained model goes through (`apply`): style codes from labels and z, G on a
curve and style codes, G's stride and gait clock. A trained model is loaded here too: the run's state
(`state`), its checkpoints (`checkpoint`, the run's model chosen by `health`) and the inference
exports with the shipped model (`pretrained.load_model`: a run or an export). Training,
generation, analysis, evaluation, the notebook and the demo all run G through `apply`; none
inspects parameters to learn what kind of G it has."""

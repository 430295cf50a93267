from .fastscnn import FastSCNN, build, fold_bn, count_params, count_params_folded, zero_init_residual, NUM_CLASSES, IGNORE_INDEX, VARIANTS, FASTSCNN_VARIANTS  # noqa: F401

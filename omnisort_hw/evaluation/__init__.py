"""Experiments on simulated data with ground truth: the paper's Table 3 comparison
(`table3`) and the random-scene sorting experiment (`sorting`)."""

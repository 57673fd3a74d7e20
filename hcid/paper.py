"""Figures the paper reports (SPEC section 6), to print beside this tool's: never to tune to."""

#: Table 2: RMS(e) in deg per model.
RMS_E_DEG = {"FB": 2.43, "FF": 1.22}
#: Section 5.2: the largest W with a false positive (FB), per method.
W_FP = {"direct": 1.2e-2, "indirect": 3.7e-2}
#: Section 5.2: FF mean nb_ft >= 2 up to this W, both methods.
W_FN = 0.26

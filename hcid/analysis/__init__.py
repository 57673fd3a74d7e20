"""What a selected model and a record say: responses and loop descriptors, residuals,
Fourier-coefficient estimates."""

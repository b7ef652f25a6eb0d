"""The optimal-control problem: its transcriptions, settings, compiled NLP functions and linear solver."""

"""gonio.rigs"""

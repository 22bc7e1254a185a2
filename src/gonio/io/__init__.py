"""gonio.io"""

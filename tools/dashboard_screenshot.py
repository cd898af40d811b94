"""The README's picture of one `dvc repro` in MLflow (docs/images/mlflow_repro.png), taken in a real browser.

    mlflow ui --backend-store-uri sqlite:///mlflow.db --port 5055 &    # after `dvc repro tour/dvc.yaml`
    python tools/dashboard_screenshot.py EXPERIMENT_ID "dvc repro 2026-..." docs/images/mlflow_repro.png

Needs Chromium, its driver and Selenium (development only, not the package's dependencies):
`apt-get install chromium chromium-driver` and `pip install selenium`. Opens the experiment's runs in
the model-training view, expands the named parent run (its stages as children) and saves the page
without the assistant panel.
"""

from __future__ import annotations

import sys
import time


def main(experiment: str, parent: str, out: str, port: int = 5055) -> None:
    from PIL import Image
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    options = webdriver.ChromeOptions()
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1500,1080", "--hide-scrollbars"):
        options.add_argument(argument)
    options.binary_location = "/usr/bin/chromium"
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    try:
        driver.get(f"http://127.0.0.1:{port}/#/experiments/{experiment}/runs?workflowType=machine_learning")
        time.sleep(8)  # the runs table loads after the page
        name = driver.find_elements(By.XPATH, f"//*[contains(text(), '{parent}')]")[0]
        name.find_element(By.XPATH, "./ancestor::*[@role='gridcell'][1]//button").click()  # the row's expander
        time.sleep(4)
        driver.save_screenshot(out)
    finally:
        driver.quit()
    image = Image.open(out)
    image.crop((0, 0, int(image.width * 0.74), image.height)).save(out, optimize=True)  # the assistant panel cut off


if __name__ == "__main__":
    main(*sys.argv[1:4])

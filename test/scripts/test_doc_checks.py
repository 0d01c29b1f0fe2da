"""The lint cases that keep the documentation honest: the module table of docs/DEVELOPING.md against
the tree (check_module_table), citations a reader can open (lint.check_references), and clang-tidy's
reasons and output parsing (check_clang_tidy). Each runs on a small tree made for the test."""
import os
import tempfile
import unittest

import check_clang_tidy
import check_module_table
import lint

HEADER = ("| folder | cmake fragment | library | node | simulator | unit tests | rostests | fuzz targets | benchmark "
          "| doc pages |\n|---|---|---|---|---|---|---|---|---|---|\n")
ROW_A = ("| `src/a/` | `cmake/modules/a.cmake` | `cnc_bridge_a` | `a_node` | | `test_a` | `a.test` | `fuzz_a` "
         "| `bench/a/` | `docs/protocols/a.md` |\n")


class Tree(unittest.TestCase):
    """A temporary repository with one module, a, laid out as the table says."""

    def setUp(self):
        self.directory = tempfile.TemporaryDirectory()
        self.addCleanup(self.directory.cleanup)
        self.root = self.directory.name
        files = {
            "CMakeLists.txt": "cnc_node(a_node src/ros/nodes/a_node.cpp)\n",
            "cmake/modules/a.cmake": "cnc_core_module(cnc_bridge_a src/a/a.cpp)\ncnc_core_gtest(test_a t.cpp)\n"
                                     "cnc_fuzz_target(fuzz_a test/fuzz/fuzz_a.cpp)\n",
            "src/a/a.cpp": "", "test/fuzz/fuzz_a.cpp": "", "test/rostest/a.test": "", "bench/a/run.sh": "",
            "docs/protocols/a.md": "# A\n\n## Haas end of transfer\n",
        }
        for path, text in files.items():
            self.write(path, text)
        self.guide(ROW_A)

    def write(self, path, text):
        full = os.path.join(self.root, path)
        os.makedirs(os.path.dirname(full), exist_ok=True)
        with open(full, "w", encoding="utf-8") as f:
            f.write(text)

    def guide(self, rows, prose=""):
        self.write("docs/DEVELOPING.md", f"# Developing\n\n{prose}\n\n## Modules\n\n{HEADER}{rows}\n## Next\n")

    def problems(self):
        saved = check_module_table.ROOT
        check_module_table.ROOT = self.root
        try:
            return check_module_table.problems()
        finally:
            check_module_table.ROOT = saved


class ModuleTable(Tree):
    def test_a_table_matching_the_tree_passes(self):
        self.assertEqual([], self.problems())

    def test_a_source_folder_without_a_row_fails(self):
        self.write("src/b/b.cpp", "")
        self.assertIn("src/b/ has no row", self.problems())

    def test_a_target_declared_nowhere_fails(self):
        self.guide(ROW_A.replace("`test_a`", "`test_gone`"))
        self.assertTrue(any("'test_gone'" in p and "no CMake target" in p for p in self.problems()), self.problems())

    def test_a_rostest_file_missing_fails(self):
        self.guide(ROW_A.replace("`a.test`", "`gone.test`"))
        self.assertTrue(any("'gone.test'" in p and "does not exist" in p for p in self.problems()), self.problems())

    def test_a_fuzz_target_bench_and_fragment_missing_from_the_table_fail(self):
        self.write("test/fuzz/fuzz_new.cpp", "")
        self.write("bench/new/run.sh", "")
        self.write("cmake/modules/new.cmake", "")
        found = self.problems()
        for name in ("fuzz_new", "bench/new/", "cmake/modules/new.cmake"):
            self.assertTrue(any(p.startswith(name + " appears in no row") for p in found), (name, found))

    def test_a_path_in_the_prose_that_does_not_exist_fails(self):
        self.guide(ROW_A, prose="The example builds src/a/xmodem.cpp and src/a/a.cpp.")
        self.assertEqual(["docs/DEVELOPING.md names src/a/xmodem.cpp, which does not exist"], self.problems())

    def test_wrong_columns_fail(self):
        self.write("docs/DEVELOPING.md", "## Modules\n\n| folder | library |\n|---|---|\n| `src/a/` | x |\n")
        self.assertEqual(1, len(self.problems()))
        self.assertIn("columns", self.problems()[0])


class References(Tree):
    def check(self, text):
        self.write("src/a/a.cpp", text)
        saved = lint.ROOT
        lint.ROOT = self.root
        try:
            return lint.check_references(["src/a/a.cpp", "docs/protocols/a.md"])
        finally:
            lint.ROOT = saved

    def test_internal_documents_design_sections_and_issues_are_refused(self):
        # Spelled in pieces so that this file does not cite them itself.
        for text in ("// as the " + "seed's capture shows", "// DESIGN " + "section 6", "// (issue " + "4)",
                     "// seed " + "6 step 2", "// shared/se" + "eds/x.md", "// opendnc_haas_xmodem_dprnt" + ".md"):
            self.assertEqual(1, len(self.check(text)), text)

    def test_random_seeds_and_fuzz_corpora_are_not_citations(self):
        for text in ("uint32_t seed = 1;", "// --seed 7", "// the seed corpus", "// probabilities and the seed."):
            self.assertEqual([], self.check(text), text)

    def test_a_cited_section_must_exist(self):
        self.assertEqual([], self.check("// docs/protocols/a.md" + "#haas-end-of-transfer"))
        found = self.check("// docs/protocols/a.md" + "#haas-start")
        self.assertEqual(1, len(found))
        self.assertIn("does not exist", found[0][1])


class ClangTidy(unittest.TestCase):
    def setUp(self):
        self.directory = tempfile.TemporaryDirectory()
        self.addCleanup(self.directory.cleanup)
        self.saved = check_clang_tidy.ROOT
        check_clang_tidy.ROOT = self.directory.name
        self.addCleanup(setattr, check_clang_tidy, "ROOT", self.saved)

    def config(self, text):
        with open(os.path.join(self.directory.name, ".clang-tidy"), "w") as f:
            f.write(text)

    def test_every_check_turned_off_needs_a_reason(self):
        self.config("# Off:\n#   misc-no-recursion: bounded.\nChecks: >\n  -*,\n  misc-*,\n  -misc-no-recursion,\n"
                    "  -misc-unused-parameters\nHeaderFilterRegex: 'x'\n")
        found = check_clang_tidy.unexplained_exclusions()
        self.assertEqual([(".clang-tidy", "misc-unused-parameters is turned off without a reason "
                                          "('#   misc-unused-parameters: why')")], found)

    def test_the_repositorys_config_gives_every_reason(self):
        check_clang_tidy.ROOT = self.saved
        self.assertEqual([], check_clang_tidy.unexplained_exclusions())

    def test_findings_are_parsed_with_file_line_and_check(self):
        output = ("/r/src/a.cpp:12:5: warning: variable 'n' is not initialized [cppcoreguidelines-init-variables]\n"
                  "/r/include/b.h:3:1: error: narrowing [bugprone-narrowing-conversions,"
                  "cppcoreguidelines-narrowing-conversions]\n  int n;\n      ^\n")
        self.assertEqual([("/r/src/a.cpp", "12", "variable 'n' is not initialized", "cppcoreguidelines-init-variables"),
                          ("/r/include/b.h", "3", "narrowing",
                           "bugprone-narrowing-conversions,cppcoreguidelines-narrowing-conversions")],
                         check_clang_tidy.FINDING.findall(output))

    def test_a_build_without_compile_commands_fails(self):
        found, checked = check_clang_tidy.findings(self.directory.name)
        self.assertEqual(0, checked)
        self.assertEqual(1, len(found))
        self.assertIn("compile_commands.json", found[0][0])


if __name__ == "__main__":
    unittest.main()

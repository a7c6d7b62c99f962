// The call into assimp (hv__assimp_import and hv__assimp_release, declared
// in mesh_internal.h), made so that a file assimp cannot read fails the read,
// and never the process.
//
// Debian builds assimp 5.2 with its own assertions on: ai_assert calls
// Assimp::aiAssertViolation, whose default handler prints to stderr and
// aborts, and a corrupt file reaches hundreds of them (a 3MF whose archive
// has no model part aborts in D3MFOpcPackage.cpp at once). Debian's library
// does not export the setter of that handler (Assimp::setAiAssertHandler),
// so the function itself is defined here: libassimp calls it through its PLT,
// and libheatvox (or a program linked with libheatvox.a) comes before
// libassimp in the dynamic linker's lookup order, so this definition is the
// one called. It throws; Importer::ReadFile catches every exception, and the
// import fails with the broken check as its message. A program that links
// libassimp ahead of libheatvox keeps assimp's aborting handler.
//
// The import goes through an Importer of the C++ API that holds the one
// reader the extension names, the others unregistered: when the file does
// not pass that reader's own signature test, Importer::ReadFile would
// otherwise hand it to each of assimp's forty other readers in turn, every
// one a parser with its own ways to fail on a file not meant for it. The
// Importer also keeps its own error message, where the C API writes one
// global string, so reads on several threads need no lock.

#include <assimp/BaseImporter.h>
#include <assimp/Importer.hpp>
#include <assimp/config.h>
#include <assimp/importerdesc.h>
#include <assimp/scene.h>

#include <cctype>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>

extern "C" {
#include "mesh_internal.h"
}

namespace
{

// The first check of assimp's that the running import broke.
thread_local std::string broken_check;

struct assimp_check_failed : std::runtime_error {
    using std::runtime_error::runtime_error;
};

} // namespace

namespace Assimp
{

// Declared by assimp's ai_assert.h in its debug builds only.
__attribute__((visibility("default"))) void aiAssertViolation(const char *expr, const char *file,
                                                              int line);

void aiAssertViolation(const char *expr, const char *file, int line)
{
    char msg[512];
    std::snprintf(msg, sizeof msg, "the file breaks assimp's check %s (%s:%d)", expr ? expr : "?",
                  file ? file : "?", line);
    if (broken_check.empty())
        broken_check = msg;
    throw assimp_check_failed(msg);
}

} // namespace Assimp

// Whether the reader desc is the one for files ending in ext (".glb"): it
// lists the extension, and it is not the glTF 1.0 reader, which shares
// glTF 2.0's extensions (heatvox reads glTF 2.0).
static bool reads(const aiImporterDesc *desc, const char *ext)
{
    if (!desc || !desc->mFileExtensions || !desc->mName ||
        !std::strcmp(desc->mName, "glTF Importer"))
        return false;
    const std::string list = std::string(" ") + desc->mFileExtensions + " ";
    std::string want = std::string(" ") + (ext + 1) + " ";
    for (char &c : want)
        c = (char)std::tolower((unsigned char)c);
    return list.find(want) != std::string::npos;
}

extern "C" const struct aiScene *hv__assimp_import(const char *path, const char *buf, size_t len,
                                                   char *err, size_t errsize, void **owner)
{
    *owner = nullptr;
    broken_check.clear();
    Assimp::Importer *imp = nullptr;
    const aiScene *sc = nullptr;
    std::string why;
    try {
        const char *slash = std::strrchr(path, '/');
        const char *ext = std::strrchr(slash ? slash + 1 : path, '.');
        imp = new Assimp::Importer();
        size_t kept = 0;
        for (size_t i = imp->GetImporterCount(); i-- > 0;) {
            if (ext && reads(imp->GetImporterInfo(i), ext)) {
                kept++;
                continue;
            }
            Assimp::BaseImporter *other = imp->GetImporter(i);
            if (imp->UnregisterLoader(other) == AI_SUCCESS)
                delete other; // unregistered readers are the caller's
        }
        // Coordinates as the file has them: no turn to y-up (COLLADA), no
        // meshes made up for skeletons, nothing read that holds no geometry.
        imp->SetPropertyInteger(AI_CONFIG_IMPORT_COLLADA_IGNORE_UP_DIRECTION, 1);
        imp->SetPropertyInteger(AI_CONFIG_IMPORT_NO_SKELETON_MESHES, 1);
        imp->SetPropertyInteger(AI_CONFIG_IMPORT_FBX_READ_ANIMATIONS, 0);
        imp->SetPropertyInteger(AI_CONFIG_IMPORT_FBX_READ_TEXTURES, 0);
        imp->SetPropertyInteger(AI_CONFIG_IMPORT_FBX_READ_CAMERAS, 0);
        imp->SetPropertyInteger(AI_CONFIG_IMPORT_FBX_READ_LIGHTS, 0);
        if (kept != 1)
            why = "assimp has no reader for this extension";
        else if (!buf)
            sc = imp->ReadFile(path, 0);
        else if (len <= 0xffffffffu) // a pipe's bytes
            sc = imp->ReadFileFromMemory(buf, len, 0, ext + 1);
        else
            why = "more than 4 GiB from a pipe";
        if (!sc && why.empty()) {
            const char *e = imp->GetErrorString();
            why = e && *e ? e : "cannot read the file";
        }
    } catch (const std::exception &e) { // one that got past assimp's own handlers
        sc = nullptr;
        why = e.what();
    } catch (...) {
        sc = nullptr;
        why = "an unknown exception";
    }
    if (!sc) {
        std::snprintf(err, errsize, "%s",
                      broken_check.empty() ? why.c_str() : broken_check.c_str());
        delete imp;
        return nullptr;
    }
    *owner = imp;
    return sc;
}

extern "C" void hv__assimp_release(void *owner)
{
    delete static_cast<Assimp::Importer *>(owner); // and its scene with it
}

// Decodes an EXR file with OpenEXR's C++ library (Imf), a reader independent
// of the Core C API that heatvox writes and reads with, and writes every
// part's channel as raw little-endian floats in file order (part by part, top
// image row first) to OUT. Exit 0 on success, 1 with a message otherwise.
//
//   exr_values FILE.exr CHANNEL OUT.raw
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputPart.h>
#include <ImfMultiPartInputFile.h>

#include <cstdio>
#include <exception>
#include <vector>

int main(int argc, char **argv)
{
    if (argc != 4) {
        std::fprintf(stderr, "usage: exr_values FILE.exr CHANNEL OUT.raw\n");
        return 2;
    }
    try {
        Imf::MultiPartInputFile file(argv[1]);
        std::FILE *out = std::fopen(argv[3], "wb");
        if (!out) {
            std::perror(argv[3]);
            return 1;
        }
        for (int p = 0; p < file.parts(); p++) {
            Imf::InputPart part(file, p);
            const Imath::Box2i dw = part.header().dataWindow();
            const long nx = dw.max.x - dw.min.x + 1, ny = dw.max.y - dw.min.y + 1;
            if (!part.header().channels().findChannel(argv[2])) {
                std::fprintf(stderr, "%s: part %d has no channel %s\n", argv[1], p, argv[2]);
                return 1;
            }
            std::vector<float> v((size_t)(nx * ny));
            Imf::FrameBuffer fb;
            char *base = (char *)(v.data() - dw.min.x - dw.min.y * nx);
            fb.insert(argv[2], Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * nx));
            part.setFrameBuffer(fb);
            part.readPixels(dw.min.y, dw.max.y);
            if (std::fwrite(v.data(), sizeof(float), v.size(), out) != v.size()) {
                std::perror(argv[3]);
                return 1;
            }
        }
        if (std::fclose(out) != 0) {
            std::perror(argv[3]);
            return 1;
        }
    } catch (const std::exception &e) {
        std::fprintf(stderr, "%s: %s\n", argv[1], e.what());
        return 1;
    }
    return 0;
}
